"""Stage 2 of a comparison reads stage 1's winner from the MLflow store (a spec's ``best_of``).

Stage 1 tunes each method on validation tasks (an Optuna sweep, one MLflow child run per trial); stage 2
runs each method's best configuration with more seeds and reports test success. The winner is chosen
here, by the sweep's finished trials alone: each trial's last value of ``best_of.metric`` (a validation
metric; its AUC is the last value of a running area), averaged over the trials of one configuration
(several seeds), best by ``mode``. Its searched values (the trial's ``config.yaml`` artifact, as the
sweep logged it) become stage 2's fixed config. No Ray; MLflow is imported on use.
"""

from __future__ import annotations

import math
import tempfile
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from copilot_ray.keys import (
    CONFIG_ARTIFACT,
    CONFIG_KEY_TAG,
    ENV_PARAM,
    ROLE_TAG,
    ROLE_TRIAL,
    SEED_PARAM,
    SWEEP_TAG,
    VARIANT_PARAM,
)


class StageError(RuntimeError):
    """Stage 1's results cannot give stage 2 a configuration (nothing finished, no such sweep...)."""


@dataclass(frozen=True)
class Winner:
    values: dict[str, Any]  # the searched settings of the best configuration
    config_key: str
    score: float  # the metric, averaged over the configuration's finished trials
    trials: int  # how many finished trials (seeds) that mean is over
    run_ids: tuple[str, ...]

    def provenance(self, sweep: str, metric: str) -> str:
        return (
            f"best of sweep {sweep!r} by {metric} = {self.score:.4g} (mean over {self.trials} finished "
            f"trial(s): {', '.join(self.run_ids)})"
        )


def _trial_values(client, run) -> dict[str, Any]:
    """The searched values of one trial run: its config.yaml artifact's `trial` (typed, as sampled)."""
    with tempfile.TemporaryDirectory() as tmp:
        try:
            local = client.download_artifacts(run.info.run_id, CONFIG_ARTIFACT, tmp)
        except Exception as err:  # noqa: BLE001 - any failure to read it is the same problem
            raise StageError(
                f"run {run.info.run_id} of sweep {run.data.tags.get(SWEEP_TAG)!r} has no readable "
                f"{CONFIG_ARTIFACT} artifact ({err})"
            ) from err
        trial = (yaml.safe_load(Path(local).read_text()) or {}).get("trial") or {}
    return {k: v for k, v in trial.items() if k not in (SEED_PARAM, VARIANT_PARAM, ENV_PARAM)}


def best_configuration(uri: str, experiment: str, sweep: str, metric: str, mode: str = "max") -> Winner:
    """The best configuration of `sweep`'s finished trials in the store at `uri` (module docstring)."""
    import mlflow

    from copilot_ray.tracking import find_runs

    client = mlflow.MlflowClient(uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        raise StageError(f"best_of: no experiment {experiment!r} in {uri}: has sweep {sweep!r} run there?")
    runs = find_runs(client, exp.experiment_id, {SWEEP_TAG: sweep, ROLE_TAG: ROLE_TRIAL})
    finished = [r for r in runs if r.info.status == "FINISHED"]
    scored = defaultdict(list)
    for run in finished:
        value = run.data.metrics.get(metric)
        if value is not None and not math.isnan(value):
            scored[run.data.tags.get(CONFIG_KEY_TAG, run.info.run_id)].append((value, run))
    if not scored:
        raise StageError(
            f"best_of: sweep {sweep!r} in {uri} (experiment {experiment!r}) has {len(runs)} trial run(s), "
            f"{len(finished)} finished, none with {metric!r}: run (or resume) that sweep first"
        )
    sign = 1.0 if mode == "max" else -1.0
    key, group = max(scored.items(), key=lambda kv: sign * sum(v for v, _ in kv[1]) / len(kv[1]))
    values = _trial_values(client, group[0][1])
    return Winner(
        values=values,
        config_key=key,
        score=sum(v for v, _ in group) / len(group),
        trials=len(group),
        run_ids=tuple(r.info.run_id for _, r in group),
    )


# ------------------------------------------------------------------------------- stage 1, as a table
@dataclass(frozen=True)
class TunedTrial:
    """One stage-1 trial as the store holds it: what it tried and what it scored on validation tasks."""

    run_id: str
    status: str  # MLflow's: FINISHED, RUNNING, KILLED, FAILED
    values: dict[str, Any]  # its searched settings ({} when its config artifact is missing)
    score: float  # the objective's last value (NaN: none logged)
    final: float  # the last validation success
    env_steps: float
    collision_checks: float  # the privilege counts it logged (0 where none)
    resets: float


def tuned_trials(uri: str, experiment: str, sweep: str, metric: str) -> list[TunedTrial]:
    """Every trial run of `sweep` in the store, finished or not, oldest first."""
    import mlflow

    from copilot_ray.keys import (
        ENV_STEPS,
        EVAL_SUCCESS,
        PRIVILEGE_COLLISION_CHECKS,
        PRIVILEGE_RESETS,
        validation_key,
    )
    from copilot_ray.tracking import find_runs

    client = mlflow.MlflowClient(uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        raise StageError(f"no experiment {experiment!r} in {uri}")
    out = []
    for run in find_runs(client, exp.experiment_id, {SWEEP_TAG: sweep, ROLE_TAG: ROLE_TRIAL}):
        m = run.data.metrics
        try:
            values = _trial_values(client, run)
        except StageError:
            values = {}
        out.append(
            TunedTrial(
                run.info.run_id,
                run.info.status,
                values,
                float(m.get(metric, math.nan)),
                float(m.get(validation_key(EVAL_SUCCESS), math.nan)),
                float(m.get(ENV_STEPS, math.nan)),
                float(m.get(PRIVILEGE_COLLISION_CHECKS, 0.0)),
                float(m.get(PRIVILEGE_RESETS, 0.0)),
            )
        )
    return out


def tuning_table(trials: list[TunedTrial], metric: str, winner: Winner | None) -> str:
    """A markdown table of one stage-1 sweep, in trial order, the winner marked."""
    chosen = set(winner.run_ids) if winner else set()
    lines = [
        f"| trial | status | searched values | {metric} | last validation success | env steps "
        "| collision checks | resets |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for i, t in enumerate(trials, start=1):
        values = ", ".join(f"{k}={_short(v)}" for k, v in sorted(t.values.items())) or "-"
        mark = " **chosen**" if t.run_id in chosen else ""
        lines.append(
            f"| {i}{mark} | {t.status.lower()} | {values} | {_num(t.score)} | {_num(t.final, '.2f')} "
            f"| {_num(t.env_steps, ',.0f')} | {_num(t.collision_checks, '.3g')} | {_num(t.resets, ',.0f')} |"
        )
    return "\n".join(lines)


def _short(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _num(x: float, fmt: str = ".3f") -> str:
    return "-" if x is None or math.isnan(x) else format(x, fmt)


def main(argv: list[str] | None = None) -> int:
    """``python -m copilot_ray.stages EXPERIMENT --tracking-uri URI``: every stage-1 sweep of a tuning
    experiment as a table of its trials on validation tasks, with the configuration stage 2 gets."""
    import argparse
    import sys

    from copilot_ray.commands import python_module
    from copilot_ray.keys import EVAL_SUCCESS_AUC, ROLE_SWEEP, validation_key
    from copilot_ray.store import missing_sqlite_file, tracking_uri_problem

    p = argparse.ArgumentParser(prog=python_module("copilot_ray.stages"), description=main.__doc__)
    p.add_argument("experiment")
    p.add_argument("--tracking-uri", required=True)
    p.add_argument("--metric", default=validation_key(EVAL_SUCCESS_AUC), help="the stage-1 objective")
    p.add_argument("--mode", choices=("max", "min"), default="max")
    args = p.parse_args(argv)
    if (why := tracking_uri_problem(args.tracking_uri)) is not None:
        print(f"error: --tracking-uri {args.tracking_uri!r} is invalid: {why}", file=sys.stderr)
        return 2
    if (missing := missing_sqlite_file(args.tracking_uri)) is not None:
        print(
            f"error: --tracking-uri {args.tracking_uri!r} is invalid: there is no store file {missing}",
            file=sys.stderr,
        )
        return 2
    import os

    import mlflow

    from copilot_ray.tracking import find_runs

    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")  # a table, not progress bars
    client = mlflow.MlflowClient(args.tracking_uri)
    exp = client.get_experiment_by_name(args.experiment)
    if exp is None:
        names = sorted(e.name for e in client.search_experiments())
        print(
            f"error: experiment {args.experiment!r} is not in {args.tracking_uri}; it has {names}",
            file=sys.stderr,
        )
        return 2
    parents = find_runs(client, exp.experiment_id, {ROLE_TAG: ROLE_SWEEP})
    for sweep in dict.fromkeys(r.data.tags[SWEEP_TAG] for r in parents):
        status = [r.info.status for r in parents if r.data.tags[SWEEP_TAG] == sweep][-1].lower()
        trials = tuned_trials(args.tracking_uri, args.experiment, sweep, args.metric)
        try:
            winner = best_configuration(args.tracking_uri, args.experiment, sweep, args.metric, args.mode)
        except StageError:
            winner = None
        print(f"### {sweep} ({status}: {len(trials)} trial run(s))\n")
        print(tuning_table(trials, args.metric, winner))
        choice = f"{winner.values} ({winner.provenance(sweep, args.metric)})" if winner else "none yet"
        print(f"\nstage 2 gets: {choice}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
