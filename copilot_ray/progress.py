"""Where a sweep file stands, read from its MLflow store: starts nothing, and works while it runs.

    python -m copilot_ray.progress SPEC.yaml [--root DIR]

One line per part: finished, running (or stopped, to be resumed) or not started; its trials finished,
in progress and to come; the env steps its trials have taken of the ones it plans (each trial counted up
to the budget); then the whole file's share done and the time left at the measured pace (`--check`'s
rates, `copilot_ray/measured_throughput.json`, scaled by what is left of each part). A comparison of
thirteen parts runs for a day on two cores; this is how a researcher sees how far it got without
reading its log.

``--root`` (default: here) is the folder the sweep was started from (a `scripts/run_at_commit.sh`
worktree): SPEC is read there, and its relative store and storage resolve there. Bad input exits 2.
No Ray; MLflow is imported to read the store.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

from copilot_ray import keys, tracking
from copilot_ray.sweep_spec import SpecError, load_specs
from copilot_ray.sweep_spec.estimate import duration_text, wall_seconds

FINISHED, RUNNING, NOT_STARTED = "finished", "running or stopped", "not started"


@dataclass(frozen=True)
class PartProgress:
    name: str
    state: str  # FINISHED, RUNNING, NOT_STARTED
    planned: int  # trials the part plans
    done: int  # trial runs FINISHED
    failed: int  # trial runs FAILED (Tune retries them from a checkpoint; the report leaves them out)
    in_progress: int  # trial runs begun and not ended (RUNNING, or KILLED when a session ended)
    env_steps: float  # env steps taken, each trial counted up to the budget
    planned_env_steps: float | None  # planned trials x budget; None without an env-step budget
    seconds_left: float | None  # at the measured pace; None without an estimate

    @property
    def share(self) -> float | None:
        if not self.planned_env_steps:
            return None
        return 1.0 if self.state == FINISHED else min(1.0, self.env_steps / self.planned_env_steps)


def part_progress(spec) -> PartProgress:
    planned = len(spec.trial_plan())
    budget = spec.stop.env_steps
    planned_steps = planned * budget if budget else None
    runs = tracking.trial_runs_in_store(spec.tracking.uri, spec.experiment, spec.name)
    finished_part, _ = tracking.sweep_runs_in_store(spec.tracking.uri, spec.experiment, spec.name)
    status = [r.info.status for r in runs]
    steps = 0.0
    for r in runs:
        taken = float(r.data.metrics.get(keys.ENV_STEPS, 0.0))
        steps += min(taken, budget) if budget else taken
    state = FINISHED if finished_part else RUNNING if runs else NOT_STARTED
    whole = wall_seconds(spec)
    part = PartProgress(
        name=spec.name,
        state=state,
        planned=planned,
        done=status.count("FINISHED"),
        failed=status.count("FAILED"),
        in_progress=sum(s in ("RUNNING", "KILLED", "SCHEDULED") for s in status),
        env_steps=steps,
        planned_env_steps=planned_steps,
        seconds_left=None,
    )
    if whole is None:
        return part
    return dataclasses.replace(part, seconds_left=whole * (1.0 - (part.share or 0.0)))


def _steps(x: float | None) -> str:
    if x is None:
        return "-"
    if x == 0:
        return "0"
    return f"{x / 1e6:.2f}M" if x >= 1e6 else f"{x / 1e3:.0f}k"


def report(specs) -> list[str]:
    parts = [part_progress(spec) for spec in specs]
    width = max(len(p.name) for p in parts)
    lines = [
        f"  {'#':>2}  {'part':<{width}}  {'state':<18}  trials done/in progress/to come  env steps taken / planned"
    ]
    for i, p in enumerate(parts, start=1):
        to_come = max(0, p.planned - p.done - p.in_progress)
        trials = f"{p.done}/{p.in_progress}/{to_come}" + (f" ({p.failed} failed)" if p.failed else "")
        share = "" if p.share is None else f" ({100 * p.share:.0f} %)"
        lines.append(
            f"  {i:>2}  {p.name:<{width}}  {p.state:<18}  {trials:<31}  "
            f"{_steps(p.env_steps)} / {_steps(p.planned_env_steps)}{share}"
        )
    finished = sum(p.state == FINISHED for p in parts)
    planned = [p.planned_env_steps for p in parts if p.planned_env_steps]
    taken = sum(p.planned_env_steps * p.share for p in parts if p.planned_env_steps)
    left = [p.seconds_left for p in parts if p.seconds_left is not None]
    unknown = sum(p.seconds_left is None for p in parts if p.state != FINISHED)
    total = (
        f"; {_steps(taken)} of {_steps(sum(planned))} env steps ({100 * taken / sum(planned):.0f} %)"
        if planned
        else ""
    )
    eta = f"; left: about {duration_text(sum(left))} at the measured pace (--check's rates)" if left else ""
    if unknown:
        eta += f" ({unknown} part(s) without an estimate not counted)"
    lines.append(f"  {finished} of {len(parts)} parts finished{total}{eta}")
    return lines


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m copilot_ray.progress", description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="the sweep file, relative to --root (the copy that runs there)")
    p.add_argument("--root", default=".", help="the folder the sweep was started from (default: here)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    root = Path(args.root).expanduser().resolve()
    if not root.is_dir():
        print(f"error: --root {args.root!r} is not a folder", file=sys.stderr)
        return 2
    spec_path = Path(args.spec).expanduser()
    spec_path = spec_path if spec_path.is_absolute() else root / spec_path
    try:
        with contextlib.chdir(root):  # relative stores and storage resolve where the sweep was started
            specs = load_specs(spec_path)
            lines = report(specs)
    except SpecError as err:
        for line in err.problems:
            print(line, file=sys.stderr)
        return 2
    print(f"{spec_path} from {root} (store {specs[0].tracking.uri}):")
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
