"""A sweep's closing summary: one row per Tune trial (its configuration, seed, status, last figures, env
steps, wall time) and the table the sweep prints, with the figures averaged over a configuration's seeds;
on the VALIDATION tasks only, and in a search without the planners' test-task figures (nothing a search
could choose by on the test tasks)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from copilot_ray.keys import (
    ENV_STEPS,
    EVAL_FRESH,
    EVAL_SUCCESS,
    EVAL_SUCCESS_AUC,
    PATH_LENGTH_VS_RRT,
    PATH_SUCCESS,
    PATHS_PREFIX,
    SEED_ERRORS,
    SEED_PARAM,
    SEED_RESULTS,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    TIME_TOTAL_S,
    result_value,
    validation_key,
)
from copilot_ray.trials.description import config_key, stacked_seeds, trial_flat


@dataclass
class TrialRow:
    trial_id: str
    config_key: str
    seed: Any
    status: str  # finished | error | unfinished
    figures: dict[str, float]  # the last evaluated value of each of SUMMARY_METRICS (NaN: not logged)
    env_steps: int
    wall_s: float
    stacked: bool = False  # a seed of a stacked trial (spec seeds_per_trial > 1)


@dataclass
class SweepOutcome:
    status: str  # finished | errored | interrupted
    exit_code: int
    rows: list[TrialRow] = field(default_factory=list)
    summary: str = ""
    tracking_uri: str = ""
    parent_run_id: str = ""
    tune_paths: list[str] = field(default_factory=list)
    wall_s: float = 0.0


# The summary's columns, where any trial logged them: every agent's headline, CO-PILOT's pair (on the
# VALIDATION tasks: what one may look at while choosing; the report shows the test tasks'), the
# planners' (Fig. 4b/4c, test tasks: they have no validation figure; left out of a search's summary,
# which must show nothing it could choose by on the test tasks: `summary_keys`).
SUMMARY_METRICS = {
    validation_key(EVAL_SUCCESS): "validation success",
    validation_key(EVAL_SUCCESS_AUC): "validation AUC",
    validation_key(SUCCESS_PLANNED): "validation planned",
    validation_key(SUCCESS_DIRECT): "validation direct",
    PATH_SUCCESS: "path success",
    PATH_LENGTH_VS_RRT: "length / RRT*",
}


def _last_row(df, column: str) -> float:
    if df is None or column not in df.columns or not len(df):
        return float("nan")
    return float(df[column].iloc[-1])


def _last_valid(df, column: str) -> float:
    if df is None or column not in df.columns:
        return float("nan")
    values = df[column].dropna()
    return float(values.iloc[-1]) if len(values) else float("nan")


def rows_from_grid(grid) -> list[TrialRow]:
    """One row per Tune trial of a ResultGrid (Result.config is RLlib's full config: use the trials); a
    stacked trial (spec `seeds_per_trial` > 1) gives a row per seed, as its seeds' own trials would."""
    analysis = grid._experiment_analysis  # noqa: SLF001 - the trials with their flat Tune configs
    rows = []
    for trial in sorted(analysis.trials, key=lambda t: t.trial_id):
        flat = trial_flat(trial.config or {})
        m = trial.last_result or {}
        df = analysis.trial_dataframes.get(trial.trial_id)
        # After Ctrl-C, Tune's cleanup marks stopped trials TERMINATED too: finished means a final result.
        if trial.status == "ERROR":
            status = "error"
        else:
            status = "finished" if trial.status == "TERMINATED" and m.get("done") else "unfinished"
        wall_s = float(m.get(TIME_TOTAL_S, 0.0) or 0.0)
        seeds = stacked_seeds(trial.config or {})
        if seeds is None:
            steps = int(result_value(m, ENV_STEPS, 0) or 0)
            rows.append(_row(trial.trial_id, flat, flat.get(SEED_PARAM), status, df, steps, wall_s))
            continue
        failed = {str(s) for s in (m.get(SEED_ERRORS) or {})}
        for seed in seeds:
            own = (m.get(SEED_RESULTS) or {}).get(str(seed), {})
            steps = int(own.get(ENV_STEPS, 0) or 0)
            seed_status = "error" if str(seed) in failed else status
            row = _row(trial.trial_id, flat, seed, seed_status, _seed_frame(df, seed), steps, wall_s)
            row.stacked = True
            rows.append(row)
    return rows


def _seed_frame(df, seed: int):
    """A stacked trial's dataframe narrowed to one seed's columns, named as a one-seed trial's."""
    if df is None:
        return None
    prefix = f"{SEED_RESULTS}/{seed}/"
    columns = [c for c in df.columns if str(c).startswith(prefix)]
    return df[columns].rename(columns={c: c[len(prefix) :] for c in columns})


def _row(trial_id, flat, seed, status, df, env_steps: int, wall_s: float) -> TrialRow:
    if df is not None and EVAL_FRESH in df.columns:
        df = df[df[EVAL_FRESH] == 1.0]  # the evaluations themselves
    return TrialRow(
        trial_id=trial_id,
        config_key=config_key(flat),
        seed=seed,
        status=status,
        # success: the last evaluation's; a path figure: the last result's (NaN where it was undefined
        # then, e.g. a length ratio with no successful path, not an older value)
        figures={
            key: (_last_row(df, key) if key.startswith(PATHS_PREFIX) else _last_valid(df, key))
            for key in SUMMARY_METRICS
        },
        env_steps=env_steps,
        wall_s=wall_s,
    )


def summary_keys(searched: bool) -> list[str]:
    """SUMMARY_METRICS' keys a sweep shows: a search (Optuna) shows no test-task figure."""
    return [k for k in SUMMARY_METRICS if not (searched and k.startswith(PATHS_PREFIX))]


def summary_metrics(rows: Sequence[TrialRow], searched: bool = False) -> dict[str, float]:
    """The parent run's metrics: per configuration, the mean over its seeds of each summary figure
    (`summary/<configuration>/<figure>`), and the best configuration's of each (`summary/best/...`)."""
    groups: dict[str, list[TrialRow]] = {}
    for row in rows:
        groups.setdefault(row.config_key, []).append(row)
    out: dict[str, float] = {}
    for key in summary_keys(searched):
        label = SUMMARY_METRICS[key]
        name = label.replace(" / ", "_per_").replace(" ", "_").replace("*", "")
        means = {}
        for config, group in groups.items():
            values = [v for r in group if not math.isnan(v := r.figures.get(key, math.nan))]
            if values:
                means[config] = sum(values) / len(values)
                out[f"summary/{_metric_name(config)}/{name}"] = means[config]
        if means and key != PATH_LENGTH_VS_RRT:  # (a shorter path is better: no "best" of a ratio)
            out[f"summary/best/{name}"] = max(means.values())
    return out


def _metric_name(text: str) -> str:
    """`text` in the characters MLflow allows in a metric name."""
    return "".join(c if c.isalnum() or c in "_-. :/" else "_" for c in text)[:200]


MIN_SEEDS_FOR_SPREAD = 5  # below it a spread says little: the range, as the report shows it


def _over_seeds(values: Sequence[float]) -> str:
    """The mean over seeds and, with fewer than 5 seeds, their range; with 5 or more, ± the sample std."""
    vals = [v for v in values if not math.isnan(v)]
    if not vals:
        return "-"
    mean = sum(vals) / len(vals)
    if len(vals) == 1:
        return f"{mean:.2f}"
    if len(vals) < MIN_SEEDS_FOR_SPREAD:
        return f"{mean:.2f} [{min(vals):.2f}, {max(vals):.2f}]"
    std = math.sqrt(sum((v - mean) ** 2 for v in vals) / (len(vals) - 1))
    return f"{mean:.2f} ± {std:.2f}"


def _shown(rows: Sequence[TrialRow], searched: bool) -> list[str]:
    """The summary's figures some trial logged (CO-PILOT's validation pair as dashes where none did)."""
    return [
        key
        for key in summary_keys(searched)
        if any(not math.isnan(r.figures.get(key, math.nan)) for r in rows)
    ] or [validation_key(SUCCESS_PLANNED), validation_key(SUCCESS_DIRECT)]


def summary_note(rows: Sequence[TrialRow], searched: bool = False) -> str:
    """What the summary's figures are: which tasks each column reads, since the report beside it shows the
    test tasks' (a search's report the validation tasks'), and how a configuration's seeds are pooled."""
    shown = _shown(rows, searched)
    validation = [SUMMARY_METRICS[k] for k in shown if not k.startswith(PATHS_PREFIX)]
    paths = [SUMMARY_METRICS[k] for k in shown if k.startswith(PATHS_PREFIX)]
    parts = []
    if validation:
        report = (
            "a report of searches alone reads these too, one with a later stage the test tasks'"
            if searched
            else "the report reads the test tasks' instead, so its figures differ"
        )
        parts.append(
            f"{', '.join(validation)}: each trial's last evaluation on the VALIDATION tasks ({report})"
        )
    if paths:
        parts.append(
            f"{', '.join(paths)}: the planner's paths on the test tasks at its last result, as in the report"
        )
    return (
        "; ".join(parts)
        + f"; mean over seeds, [range] with fewer than {MIN_SEEDS_FOR_SPREAD} seeds, ± sample std with "
        f"{MIN_SEEDS_FOR_SPREAD} or more."
    )


def summary_table(rows: Sequence[TrialRow], searched: bool = False) -> str:
    """A markdown table per configuration: seeds, the mean over seeds of the final success with their range
    (fewer than 5 seeds) or ± their sample std (`searched`: a search's, without test-task figures)."""
    groups: dict[str, list[TrialRow]] = {}
    for row in rows:
        groups.setdefault(row.config_key, []).append(row)
    shown = _shown(rows, searched)
    header = ["configuration", "seeds", *(SUMMARY_METRICS[key] for key in shown)]
    header += ["env steps", "wall s/trial", "status"]
    lines = [header]
    for key, group in groups.items():
        statuses = sorted({r.status for r in group})
        lines.append(
            [
                key,
                ",".join(str(r.seed) for r in group),
                *(_over_seeds([r.figures.get(key, math.nan) for r in group]) for key in shown),
                f"{sum(r.env_steps for r in group) / len(group):,.0f}",
                f"{sum(r.wall_s for r in group) / len(group):.0f}",
                "/".join(statuses),
            ]
        )
    widths = [max(len(str(line[c])) for line in lines) for c in range(len(header))]

    def fmt(cells):
        return "| " + " | ".join(str(c).ljust(w) for c, w in zip(cells, widths, strict=True)) + " |"

    out = [fmt(lines[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    out += [fmt(line) for line in lines[1:]]
    return "\n".join(out)
