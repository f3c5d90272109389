"""Where a sweep file stands, read from its MLflow store: starts nothing, and works while it runs.

    python -m copilot_ray.progress SPEC.yaml [--root DIR]

One line per part: finished, running (or stopped, to be resumed) or not started; its trials finished,
in progress and to come; the env steps its trials have taken of the ones it plans (each trial counted up
to the budget); then the whole file's share done and the time left. The time left is read off the store
where it can be: each part's own trials' pace (their env steps over their `time_total_s`, side by side as
the spec runs them), else that of the part of the same algorithm with the longest trials in the file, else
`--check`'s rates (`copilot_ray/measured_throughput.json`); the trials left run on the part's
`max_concurrent_trials` slots, begun ones first. A comparison of thirteen parts runs for a day on two
cores; this is how a researcher sees how far it got without reading its log.

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
from copilot_ray.commands import python_module
from copilot_ray.store import missing_sqlite_file
from copilot_ray.sweep_spec import SpecError, load_specs
from copilot_ray.sweep_spec.estimate import duration_text, wall_seconds

FINISHED, RUNNING, NOT_STARTED = "finished", "running or stopped", "not started"
# Where a part's time left comes from (`PartProgress.pace_from`).
OWN, SAME_ALGORITHM, CHECK_RATES = "its own trials", "its algorithm's longest part here", "--check's rates"
MIN_OBSERVED_S = 600.0  # less running than this gives too noisy a pace


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
    seconds_left: float | None  # at the pace below; None without an estimate
    pace_from: str | None = None  # OWN, SAME_ALGORITHM or CHECK_RATES

    @property
    def share(self) -> float | None:
        if not self.planned_env_steps:
            return None
        return 1.0 if self.state == FINISHED else min(1.0, self.env_steps / self.planned_env_steps)


def _runs(spec) -> list:
    return tracking.trial_runs_in_store(spec.tracking.uri, spec.experiment, spec.name)


@dataclass(frozen=True)
class Pace:
    """How a part's trials ran, side by side as its spec runs them (from their time_total_s against
    env steps): `env_steps_per_s` after each trial's first result, and `setup_s`, what that first result
    took beyond it (CO-PILOT's planner warm start, Ray's start)."""

    env_steps_per_s: float
    setup_s: float
    longest_trial: float  # env steps of its longest trial: longer trials, a steadier figure

    def trial_seconds(self, env_steps: float, begun: bool) -> float:
        return (0.0 if begun else self.setup_s) + env_steps / self.env_steps_per_s


def observed_pace(spec, runs) -> Pace | None:
    """The pace of `runs` (one part's trials), from each trial's first result to its last; None
    before MIN_OBSERVED_S of that in all."""
    steps = seconds = setup = 0.0
    begun, longest = 0, 0.0
    for r in runs:
        history = tracking.metric_history(
            spec.tracking.uri, r.info.run_id, keys.TIME_TOTAL_S
        )  # kept across restores
        if len(history) < 2:
            continue
        (s0, t0), (s1, t1) = history[0], history[-1]
        steps, seconds = steps + s1 - s0, seconds + t1 - t0
        setup += t0 - s0 * (t1 - t0) / max(s1 - s0, 1)
        begun, longest = begun + 1, max(longest, s1)
    if seconds < MIN_OBSERVED_S or steps <= 0:
        return None
    return Pace(steps / seconds, max(0.0, setup / begun), longest)


@dataclass(frozen=True)
class Observed:
    """What the store holds of one part's trials, read once: their runs and their pace."""

    runs: list
    pace: Pace | None


def observe(spec) -> Observed:
    runs = _runs(spec)
    return Observed(runs, observed_pace(spec, runs))


def paces_by_algorithm(specs, observed: dict[str, Observed] | None = None) -> dict[str, Pace]:
    """Each algorithm's pace in this file, from its part with the longest trials (a part without
    trials of its own yet borrows it); `observed`: each part's, by name, when already read."""
    best: dict[str, Pace] = {}
    for spec in specs:
        found = (observed[spec.name] if observed else observe(spec)).pace
        if found is not None and found.longest_trial > getattr(best.get(spec.algorithm), "longest_trial", 0):
            best[spec.algorithm] = found
    return best


def planned_runs(spec) -> int:
    """The MLflow runs a part makes: one per trial, one per seed of a stacked trial (a stack's seeds
    take turns in their trial, so each is timed, and scheduled here, as a trial of its own)."""
    return len(spec.trial_plan()) * spec.seeds_per_trial


def _seconds_left(spec, taken: list[float], pace: Pace) -> float:
    """The trials left (begun ones first, then the planned ones not begun) in list scheduling on the
    part's max_concurrent_trials slots."""
    budget = float(spec.stop.env_steps)
    trials = [pace.trial_seconds(max(0.0, budget - t), begun=t > 0) for t in taken]
    trials += [pace.trial_seconds(budget, begun=False)] * max(0, planned_runs(spec) - len(taken))
    slots = [0.0] * max(1, spec.resources.max_concurrent_trials)
    for seconds in trials:
        slots[slots.index(min(slots))] += seconds
    return max(slots)


def part_progress(
    spec, paces: dict[str, Pace] | None = None, observed: Observed | None = None
) -> PartProgress:
    """Where one part stands; its time left at its own trials' pace, else `paces[spec.algorithm]`, else
    --check's rates. `observed`: what the store holds of it, when already read."""
    planned = planned_runs(spec)
    budget = spec.stop.env_steps
    planned_steps = planned * budget if budget else None
    observed = observed or observe(spec)
    runs = observed.runs
    finished_part, _ = tracking.sweep_runs_in_store(spec.tracking.uri, spec.experiment, spec.name)
    status = [r.info.status for r in runs]
    taken = [float(r.data.metrics.get(keys.ENV_STEPS, 0.0)) for r in runs]
    steps = sum(min(t, budget) if budget else t for t in taken)
    state = FINISHED if finished_part else RUNNING if runs else NOT_STARTED
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
    if state == FINISHED:
        return dataclasses.replace(part, seconds_left=0.0)
    own = observed.pace
    if budget and (own is not None or spec.algorithm in (paces or {})):
        pace, source = (own, OWN) if own is not None else (paces[spec.algorithm], SAME_ALGORITHM)
        return dataclasses.replace(part, seconds_left=_seconds_left(spec, taken, pace), pace_from=source)
    whole = wall_seconds(spec)
    if whole is None:
        return part
    return dataclasses.replace(part, seconds_left=whole * (1.0 - (part.share or 0.0)), pace_from=CHECK_RATES)


def _steps(x: float | None) -> str:
    if x is None:
        return "-"
    if x == 0:
        return "0"
    return f"{x / 1e6:.2f}M" if x >= 1e6 else f"{x / 1e3:.0f}k"


def report(specs) -> list[str]:
    observed = {spec.name: observe(spec) for spec in specs}  # the store read once per part
    paces = paces_by_algorithm(specs, observed)
    parts = [part_progress(spec, paces, observed[spec.name]) for spec in specs]
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
    sources = [p.pace_from for p in parts if p.state != FINISHED and p.pace_from]
    paced = ", ".join(f"{s}: {sources.count(s)}" for s in (OWN, SAME_ALGORITHM, CHECK_RATES) if s in sources)
    # Every part finished: nothing is left to estimate (not "about 0 s, paced by" nothing).
    eta = f"; left: about {duration_text(sum(left))} (parts paced by {paced})" if left and paced else ""
    if unknown:
        eta += f" ({unknown} part(s) without an estimate not counted)"
    lines.append(f"  {finished} of {len(parts)} parts finished{total}{eta}")
    return lines


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog=python_module("copilot_ray.progress"), description=__doc__.split("\n\n")[0]
    )
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
    except SpecError as err:
        for line in err.problems:
            print(line, file=sys.stderr)
        return 2
    uris = dict.fromkeys(spec.tracking.uri for spec in specs)
    missing = [path for uri in uris if (path := missing_sqlite_file(uri)) is not None]
    if len(missing) == len(uris):  # nothing of it ran from --root (or a typo): say so, create no store
        print(
            f"error: tracking.uri {next(iter(uris))!r} of {spec_path} is invalid: there is no store file "
            f"{missing[0]} (nothing of it has run from {root}; --root names the folder it was started from)",
            file=sys.stderr,
        )
        return 2
    with contextlib.chdir(root):
        lines = report(specs)
    print(f"{spec_path} from {root} (store {specs[0].tracking.uri}):")
    for line in lines:
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
