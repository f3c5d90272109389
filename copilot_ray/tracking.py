"""MLflow wiring, in one place: where the store is, which metrics go there, and at which step.

Every curve is plotted against environment steps, so metrics are logged with
`step = num_env_steps_sampled_lifetime`.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

ENV_STEPS_KEY = "env_runners/num_env_steps_sampled_lifetime"
MLFLOW_PARAM_LIMIT = 500  # MLflow rejects longer param values


def default_tracking_uri(directory: str | Path = ".") -> str:
    """An embedded SQLite store (MLflow 3 refuses the plain ./mlruns file store by default)."""
    return f"sqlite:///{(Path(directory) / 'mlflow.db').resolve()}"


def flatten(d: Mapping[str, Any], prefix: str = "", sep: str = "/") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in d.items():
        name = f"{prefix}{sep}{key}" if prefix else str(key)
        if isinstance(value, Mapping):
            out.update(flatten(value, name, sep))
        else:
            out[name] = value
    return out


def metrics_from_result(result: Mapping[str, Any]) -> dict[str, float]:
    """The numeric metrics worth tracking from an RLlib result dict (flattened with '/')."""
    flat = flatten(result)
    keep = ("copilot/", "env_runners/", "learners/default_policy/", "timers/")
    out = {}
    for key, value in flat.items():
        if not key.startswith(keep):
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if value != value:  # NaN: MLflow accepts it, but it breaks comparisons in the UI
            continue
        out[key] = float(value)
    return out


def git_commit() -> str:
    try:
        root = Path(__file__).resolve().parent.parent
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def params_for_mlflow(config: Mapping[str, Any]) -> dict[str, str]:
    """Flattened params, each value truncated to MLflow's limit (the full config is an artifact)."""
    out = {}
    for key, value in flatten(config, sep=".").items():
        text = repr(value) if not isinstance(value, str) else value
        out[key[:250]] = text[:MLFLOW_PARAM_LIMIT]
    return out


class MlflowRun:
    """A thin context manager around one MLflow run (used by `copilot_ray.train`)."""

    def __init__(self, tracking_uri: str, experiment: str, run_name: str, tags: Mapping[str, str]):
        import mlflow

        os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
        self.mlflow = mlflow
        self.client = mlflow.MlflowClient(tracking_uri)
        exp = self.client.get_experiment_by_name(experiment)
        exp_id = exp.experiment_id if exp else self.client.create_experiment(experiment)
        self.run = self.client.create_run(exp_id, run_name=run_name, tags=dict(tags))
        self.run_id = self.run.info.run_id

    def log_params(self, params: Mapping[str, str]) -> None:
        from mlflow.entities import Param

        items = [Param(k, v) for k, v in params.items()]
        for i in range(0, len(items), 100):
            self.client.log_batch(self.run_id, params=items[i : i + 100])

    def log_metrics(self, metrics: Mapping[str, float], step: int) -> None:
        import time

        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        items = [Metric(k, v, now, step) for k, v in metrics.items()]
        for i in range(0, len(items), 500):
            self.client.log_batch(self.run_id, metrics=items[i : i + 500])

    def log_artifacts(self, path: str | Path, artifact_path: str | None = None) -> None:
        self.client.log_artifacts(self.run_id, str(path), artifact_path)

    def log_artifact(self, path: str | Path, artifact_path: str | None = None) -> None:
        self.client.log_artifact(self.run_id, str(path), artifact_path)

    def end(self, status: str = "FINISHED") -> None:
        self.client.set_terminated(self.run_id, status=status)
