"""Every run's metrics as one long table, `metrics.csv.gz` next to the report: what the report was
computed from, for anyone who wants other numbers than the report's (as `docs/maze_learning/
metrics.csv.gz` was written by hand before).

Columns: run (name), config (the report's label), seed, metric, env_steps (MLflow's step), value. Kept:
the namespaces copilot/ and paths/ and the env-step counter; every logged row, as logged (no fresh-only
filter: the `copilot/eval/fresh` column says which rows of the evaluation metrics are real evaluations).
A report on validation tasks (a search's) leaves out the test tasks' copilot/eval/ figures.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from copilot_ray.keys import COPILOT_PREFIX, ENV_STEPS, EVAL_FRESH, EVAL_PREFIX, PATHS_PREFIX

from .load import TEST, VALIDATION, Sweep, metric_histories

METRICS_CSV = "metrics.csv.gz"
COLUMNS = ("run", "config", "seed", "metric", "env_steps", "value")


def exported(key: str, tasks: str = TEST) -> bool:
    """A report on validation tasks (a search's) exports nothing measured on the test tasks."""
    if tasks == VALIDATION and (
        key.startswith(PATHS_PREFIX) or (key.startswith(EVAL_PREFIX) and key != EVAL_FRESH)
    ):
        return False
    return key.startswith((COPILOT_PREFIX, PATHS_PREFIX)) or key == ENV_STEPS


def metrics_frame(sweep: Sweep, labels: dict[str, str]) -> pd.DataFrame:
    """One row per logged point of every exported metric of every trial (failed ones too); `labels`:
    run id -> configuration label (the config key when a run has none)."""
    parts = []
    for t in sweep.trials:
        keys = sorted(k for k in t.latest if exported(k, sweep.tasks))
        histories = metric_histories(t.tracking_uri or sweep.tracking_uri, t.run_id, keys)
        for key, (steps, values) in histories.items():
            parts.append(
                pd.DataFrame(
                    {
                        "run": t.run_name,
                        "config": labels.get(t.run_id, t.config_key),
                        "seed": t.seed,
                        "metric": key,
                        "env_steps": steps.astype("int64"),
                        "value": values,
                    }
                )
            )
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=list(COLUMNS))


def write_metrics_csv(sweep: Sweep, labels: dict[str, str], out_dir: Path) -> Path:
    path = out_dir / METRICS_CSV
    # mtime 0: the same runs give the same bytes
    metrics_frame(sweep, labels).to_csv(path, index=False, compression={"method": "gzip", "mtime": 0})
    return path
