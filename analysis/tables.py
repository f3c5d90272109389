"""The per-configuration summary table, as a pandas DataFrame, CSV (full precision, one number per
column) and Markdown (rounded, CIs in brackets; no `tabulate` dependency)."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from copilot_ray.keys import EVAL_SUCCESS, SUCCESS_DIRECT, SUCCESS_PLANNED

from .aggregate import THRESHOLDS, ConfigSummary

# success: what every algorithm reports (copilot/eval/success); planned / direct: where an algorithm has them
SHORT = {EVAL_SUCCESS: "success", SUCCESS_PLANNED: "planned", SUCCESS_DIRECT: "direct"}
NOT_REACHED = "not reached"


def summary_frame(configs: list[ConfigSummary]) -> pd.DataFrame:
    rows = []
    for c in configs:
        row: dict[str, object] = {"configuration": c.label, "config_key": c.key, "n_seeds": c.n_seeds}
        for metric, short in SHORT.items():
            m = c.metrics.get(metric)
            row[f"{short}_final_iqm"] = m.final_iqm if m else math.nan
            row[f"{short}_final_ci_low"] = m.final_low if m else math.nan
            row[f"{short}_final_ci_high"] = m.final_high if m else math.nan
            row[f"{short}_final_env_steps"] = m.final_step if m else math.nan
            for thr in THRESHOLDS:
                steps, reached = m.to_threshold[thr] if m else (math.nan, 0)
                # inf (not reached by the IQM's seeds) is written as text so a CSV reader cannot mistake it.
                row[f"{short}_steps_to_{thr:g}"] = NOT_REACHED if steps == math.inf else steps
                row[f"{short}_seeds_reaching_{thr:g}"] = reached
        row["wall_time_s_mean"] = c.wall_time_s
        rows.append(row)
    return pd.DataFrame(rows)


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


def markdown(frame: pd.DataFrame) -> str:
    header = ["configuration", "seeds"]
    for short in SHORT.values():
        header.append(f"{short} final IQM [95% CI]")
    for short in SHORT.values():
        for thr in THRESHOLDS:
            header.append(f"{short} steps to {thr:g} (seeds)")
    header.append("wall time (mean)")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for _, r in frame.iterrows():
        cells = [str(r["configuration"]), str(r["n_seeds"])]
        for short in SHORT.values():
            cells.append(
                f"{_num(r[f'{short}_final_iqm'], '.3f')} "
                f"[{_num(r[f'{short}_final_ci_low'], '.3f')}, {_num(r[f'{short}_final_ci_high'], '.3f')}]"
            )
        for short in SHORT.values():
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
