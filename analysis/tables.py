"""The per-configuration summary table, as a pandas DataFrame, CSV (full precision, one number per
column) and Markdown (rounded, each cell saying what it is: "IQM x [95% CI a, b]" from 5 seeds on,
"mean x, range over n seeds: [a, b]" below; no `tabulate` dependency), and the probability-of-improvement
table of CO-PILOT's default over the best other method.

Headline figures are final success (each seed's last evaluation) and the normalised area under the
success curve; never the best evaluation. Beside them, what each configuration used: env steps and its
privileges (copilot_ray.privileges), named and counted.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from copilot_ray.keys import (
    EVAL_SUCCESS,
    PRIVILEGE_COLLISION_CHECKS,
    PRIVILEGE_MAP_QUERIES,
    PRIVILEGE_RESETS,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
)

from . import stats
from .aggregate import THRESHOLDS, ConfigSummary, MetricSummary, headline_metric, improvement_pairs

# success: what every algorithm reports (copilot/eval/success); planned / direct: where an algorithm has them
SHORT = {EVAL_SUCCESS: "success", SUCCESS_PLANNED: "planned", SUCCESS_DIRECT: "direct"}
# the privilege counters' columns (final cumulative count, mean over seeds)
COUNTS = {
    PRIVILEGE_COLLISION_CHECKS: "collision_checks",
    PRIVILEGE_RESETS: "resets",
    PRIVILEGE_MAP_QUERIES: "map_queries",
}
NOT_REACHED = "not reached"


def summary_frame(configs: list[ConfigSummary]) -> pd.DataFrame:
    rows = []
    for c in configs:
        row: dict[str, object] = {
            "configuration": c.label,
            "config_key": c.key,
            "algorithm": c.algorithm,
            "n_seeds": c.n_seeds,
            "privileges": c.privileges,
            "env_steps": c.env_steps,
        }
        row.update({name: c.privilege_counts.get(key, math.nan) for key, name in COUNTS.items()})
        for metric, short in SHORT.items():
            row.update(_metric_columns(c.metrics.get(metric), short))
        row["wall_time_s_mean"] = c.wall_time_s
        rows.append(row)
    return pd.DataFrame(rows)


def _metric_columns(m: MetricSummary | None, short: str) -> dict[str, object]:
    none = stats.SeedSummary(0, math.nan, math.nan, math.nan)
    row: dict[str, object] = {f"{short}_n_seeds": m.n_seeds if m else 0}
    for what, s in (("final", m.final if m else none), ("auc", m.auc if m else none)):
        row[f"{short}_{what}"] = s.point
        row[f"{short}_{what}_estimator"] = s.estimator if s.n else ""
        row[f"{short}_{what}_low"] = s.low  # CI with >= 5 seeds, else the seeds' min
        row[f"{short}_{what}_high"] = s.high
        row[f"{short}_{what}_interval"] = s.interval  # "95% CI", "range" or "n = 1"
        row[f"{short}_{what}_n_seeds"] = s.n
    row[f"{short}_auc_from"], row[f"{short}_auc_to"] = m.auc_window if m else (math.nan, math.nan)
    row[f"{short}_final_env_steps"] = m.final_step if m else math.nan
    for thr in THRESHOLDS:
        steps, reached = m.to_threshold[thr] if m else (math.nan, 0)
        # inf (not reached by the IQM's seeds) is written as text so a CSV reader cannot mistake it.
        row[f"{short}_steps_to_{thr:g}"] = NOT_REACHED if steps == math.inf else steps
        row[f"{short}_seeds_reaching_{thr:g}"] = reached
    return row


def write_csv(frame: pd.DataFrame, path: Path) -> Path:
    frame.to_csv(path, index=False)
    return path


def _num(x, fmt: str) -> str:
    if isinstance(x, str):
        return x
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return format(x, fmt)


def _steps(x) -> str:
    if isinstance(x, str) or x is None or (isinstance(x, float) and math.isnan(x)):
        return _num(x, "")
    return f"{x:,.0f}"


def _estimate(r, prefix: str) -> str:
    """A cell that says what it is (`stats.SeedSummary.text`), from the frame's columns."""
    s = stats.SeedSummary(int(r[f"{prefix}_n_seeds"]), r[prefix], r[f"{prefix}_low"], r[f"{prefix}_high"])
    return s.text()


def shown_metrics(frame: pd.DataFrame) -> list[str]:
    """The success metrics some configuration has (a sweep of one algorithm has no column of another's)."""
    return [s for s in SHORT.values() if (frame[f"{s}_n_seeds"] > 0).any()] if len(frame) else []


def markdown(frame: pd.DataFrame) -> str:
    shorts = shown_metrics(frame)
    header = [
        "configuration",
        "seeds",
        "privileges",
        "env steps",
        "collision checks",
        "resets",
        "map queries",
    ]
    for short in shorts:
        header += [f"{short} final", f"{short} AUC"]
        header += [f"{short} steps to {thr:g} (seeds)" for thr in THRESHOLDS]
    header.append("wall time (mean)")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for _, r in frame.iterrows():
        cells = [str(r["configuration"]), str(r["n_seeds"]), str(r["privileges"]), _steps(r["env_steps"])]
        cells += [_steps(r[name]) for name in COUNTS.values()]
        for short in shorts:
            cells += [_estimate(r, f"{short}_final"), _estimate(r, f"{short}_auc")]
            for thr in THRESHOLDS:
                cells.append(
                    f"{_steps(r[f'{short}_steps_to_{thr:g}'])} ({r[f'{short}_seeds_reaching_{thr:g}']}/{r['n_seeds']})"
                )
        cells.append(_duration(r["wall_time_s_mean"]))
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _duration(seconds: float) -> str:
    if seconds is None or math.isnan(seconds):
        return "-"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.2f} h"


# ---------------------------------------------------------------------------------------------- P(X > Y)


def improvement_frame(
    configs: list[ConfigSummary], reps: int = stats.DEFAULT_REPS, seed: int = 0
) -> pd.DataFrame:
    """One row per CO-PILOT default configuration: P(it beats the best other method) on final success
    and on the success AUC, from the seeds' scores (`stats.improvement`)."""
    metric = headline_metric(configs)
    rows = []
    for x, y in improvement_pairs(configs, metric):
        mx, my = x.metrics[metric], y.metrics[metric]
        row: dict[str, object] = {"copilot": x.label, "other": y.label, "metric": metric}
        for what, a, b in (("final", mx.finals, my.finals), ("auc", mx.aucs, my.aucs)):
            imp = stats.improvement(a, b, reps=reps, seed=seed)
            row[f"p_{what}"] = imp.p if imp.available else math.nan
            row[f"p_{what}_low"], row[f"p_{what}_high"] = imp.low, imp.high
            row[f"p_{what}_text"] = imp.text()
        rows.append(row)
    return pd.DataFrame(rows)


def improvement_markdown(frame: pd.DataFrame) -> str:
    header = ["CO-PILOT (default)", "best other method", "P(final success higher)", "P(AUC higher)"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for _, r in frame.iterrows():
        cells = [str(r["copilot"]), str(r["other"]), str(r["p_final_text"]), str(r["p_auc_text"])]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"
