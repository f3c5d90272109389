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
