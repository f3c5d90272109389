"""The per-configuration summary tables, as a pandas DataFrame, CSV (full precision, one number per
column) and Markdown / HTML (`Table`: rounded, readable headers, each cell saying what it is: "IQM x [95% CI
a, b]" from 5 seeds on, "mean x, range over n seeds: [a, b]" below; no `tabulate` dependency), and the
probability-of-improvement table of CO-PILOT's default over the best other method.

Two tables, so that each fits a page: the headline (`headline_table`: configuration, seeds, privileges, env
steps and privilege counts, final test success and its area under the curve, the success every method
reports) and the details (`details_table`: one row per configuration and success metric, the planned /
direct pair where an algorithm has it, steps to thresholds, wall time). Headline figures are final success
(each seed's success at one common env step, about the budget) and the normalised area under the success
curve; never the best evaluation.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from copilot_ray.keys import (
    EVAL_SUCCESS,
    PLANNER_WARM_START_COST,
    PRIVILEGE_COLLISION_CHECKS,
    PRIVILEGE_MAP_QUERIES,
    PRIVILEGE_RESETS,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
)

from . import stats
from .aggregate import (
    THRESHOLDS,
    ConfigSummary,
    MetricSummary,
    follows_plan,
    headline_metric,
    improvement_pairs,
)
from .load import natural_key

# success: what every algorithm reports (copilot/eval/success); planned / direct: where an algorithm has them
SHORT = {EVAL_SUCCESS: "success", SUCCESS_PLANNED: "planned", SUCCESS_DIRECT: "direct"}
# the privilege counters' columns (final cumulative count, mean over seeds)
COUNTS = {
    PRIVILEGE_COLLISION_CHECKS: "collision_checks",
    PRIVILEGE_RESETS: "resets",
    PRIVILEGE_MAP_QUERIES: "map_queries",
}
NOT_REACHED = "not reached"


def summary_frame(configs: list[ConfigSummary], tasks: str = "test") -> pd.DataFrame:
    """One row per configuration (its figures on `tasks`' evaluations: `frame.attrs["tasks"]`)."""
    rows = []
    for c in configs:
        row: dict[str, object] = {
            "configuration": c.label,
            "config_key": c.key,
            "algorithm": c.algorithm,
            "follows_plan": follows_plan(c.algorithm),
            "n_seeds": c.n_seeds,
            "privileges": c.privileges,
            "env_steps": c.env_steps,
        }
        row.update({name: c.privilege_counts.get(key, math.nan) for key, name in COUNTS.items()})
        for metric, short in SHORT.items():
            row.update(_metric_columns(c.metrics.get(metric), short))
        row["wall_time_s_mean"] = c.wall_time_s
        rows.append(row)
    frame = pd.DataFrame(rows)
    frame.attrs["tasks"] = tasks
    return frame


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
    row[f"{short}_evaluations"] = m.evaluations if m else math.nan
    row[f"{short}_evaluation_gap"] = m.evaluation_gap if m else math.nan
    for thr in THRESHOLDS:
        steps, reached = m.to_threshold[thr] if m else (math.nan, 0)
        # inf (not reached by the IQM's seeds) is written as text so a CSV reader cannot mistake it.
        row[f"{short}_steps_to_{thr:g}"] = NOT_REACHED if steps == math.inf else steps
        row[f"{short}_seeds_reaching_{thr:g}"] = reached
    return row


def write_csv(frame: pd.DataFrame, path: Path) -> Path:
    """The frame as CSV, without its "_"-led columns (the page's own copies of figures)."""
    frame.drop(columns=[c for c in frame.columns if str(c).startswith("_")]).to_csv(path, index=False)
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


def _count(x) -> str:
    """A mean count over seeds: 20, 12.5."""
    return _num(x if isinstance(x, str) or math.isnan(x) else round(float(x), 1), "g")


def _estimate(r, prefix: str) -> str:
    """A cell that says what it is (`stats.SeedSummary.text`), from the frame's columns."""
    s = stats.SeedSummary(int(r[f"{prefix}_n_seeds"]), r[prefix], r[f"{prefix}_low"], r[f"{prefix}_high"])
    return s.text()


def shown_metrics(frame: pd.DataFrame) -> list[str]:
    """The success metrics some configuration has (a sweep of one algorithm has no column of another's)."""
    return [s for s in SHORT.values() if (frame[f"{s}_n_seeds"] > 0).any()] if len(frame) else []


@dataclass
class Table:
    """A table as the report shows it: readable headers, formatted cells; Markdown and HTML."""

    header: list[str]
    rows: list[list[str]] = field(default_factory=list)

    def markdown(self) -> str:
        lines = ["| " + " | ".join(self.header) + " |", "|" + "---|" * len(self.header)]
        lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in self.rows]
        return "\n".join(lines) + "\n"

    def html(self) -> str:
        head = "".join(f"<th>{html.escape(h)}</th>" for h in self.header)
        body = "".join(
            "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in self.rows
        )
        return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def headline_short(frame: pd.DataFrame) -> str:
    """The success the headline shows: `success` (what every method reports), `planned` for older runs."""
    shown = shown_metrics(frame)
    return "success" if "success" in shown or not shown else shown[0]


def headline_table(frame: pd.DataFrame) -> Table:
    """One row per configuration: what it used (env steps, privileges and their counts) and its final
    test success and success AUC (`headline_short`)."""
    short = headline_short(frame)
    what = "" if short == "success" else f" ({short})"
    success = bool(shown_metrics(frame))  # planners alone have none: no columns of dashes
    header = [
        "configuration",
        "seeds",
        "privileges",
        "env steps",
        "collision checks",
        "resets",
        "map queries",
    ]
    tasks = frame.attrs.get("tasks", "test")
    # the agent alone beside a method that plans (the paper's "agent only" reading), once any row has one
    alone = success and short == "success" and _plans_somewhere(frame)
    table = Table(
        header
        + ([f"final {tasks} success{what}", f"{tasks} success AUC{what}"] if success else [])
        + ([f"final {tasks} success, agent alone"] if alone else [])
    )
    for _, r in frame.iterrows():
        cells = [str(r["configuration"]), str(r["n_seeds"]), str(r["privileges"]), _steps(r["env_steps"])]
        cells += [_steps(r[name]) for name in COUNTS.values()]
        if success:
            cells += [_estimate(r, f"{short}_final"), _estimate(r, f"{short}_auc")]
        if alone:
            cells.append(_agent_alone(r))
        table.rows.append(cells)
    return table


def _same_figure(r: pd.Series, a: str, b: str) -> bool:
    """Whether two metrics' final figures of a row are one and the same (a method without a plan reports
    its agent's success as its success)."""
    return all(r.get(f"{a}_final{s}") == r.get(f"{b}_final{s}") for s in ("", "_low", "_high"))


def _without_plan(r: pd.Series) -> bool:
    """Whether a row's success is its agent alone: by what its algorithm declares, not by its figures
    (a planning method whose plans and agent alone end level, e.g. both at 0, still plans); by the
    figures only for an algorithm this checkout does not have."""
    plans = r.get("follows_plan")
    if plans is None or (isinstance(plans, float) and math.isnan(plans)):
        return _same_figure(r, "direct", "success")
    return not plans


def _plans_somewhere(frame: pd.DataFrame) -> bool:
    return any(r.get("direct_n_seeds", 0) > 0 and not _without_plan(r) for _, r in frame.iterrows())


def _agent_alone(r: pd.Series) -> str:
    if not r.get("direct_n_seeds", 0) > 0:
        return "-"
    return "= its success (no plan)" if _without_plan(r) else _estimate(r, "direct_final")


def details_table(frame: pd.DataFrame) -> Table:
    """One row per configuration and success metric it has (success; planned and direct where it has
    them): final, AUC, env steps to each threshold (seeds that reached it), the env step the final is
    read at, the evaluations up to it (and the median env steps between two: the cadence), wall time. A metric that equals another in every figure is one row ("success = planned")."""
    table = Table(
        [
            "configuration",
            "metric",
            "final",
            "AUC",
            *(f"env steps to {thr:g} (seeds)" for thr in THRESHOLDS),
            "final at (env steps)",
            "evaluations to it (median gap)",
            "wall time (mean)",
        ]
    )
    shorts = shown_metrics(frame)
    for _, r in frame.iterrows():
        names: dict[str, str] = {}  # metric shown -> its name in the row
        for s in (s for s in shorts if r[f"{s}_n_seeds"] > 0):
            kept = next((k for k in names if _same(r, k, s)), None)
            if kept is None:
                names[s] = s
            else:  # e.g. CO-PILOT's success is its planned success: one row "success = planned"
                names[kept] += f" = {s}"
        for s, name in names.items():
            cells = [str(r["configuration"]), name, _estimate(r, f"{s}_final"), _estimate(r, f"{s}_auc")]
            for thr in THRESHOLDS:
                cells.append(
                    f"{_steps(r[f'{s}_steps_to_{thr:g}'])} ({r[f'{s}_seeds_reaching_{thr:g}']}/{r['n_seeds']})"
                )
            cells += [
                _steps(r[f"{s}_final_env_steps"]),
                f"{_count(r[f'{s}_evaluations'])} ({_steps(r[f'{s}_evaluation_gap'])})",
                _duration(r["wall_time_s_mean"]),
            ]
            table.rows.append(cells)
    return table


def _same(r, a: str, b: str) -> bool:
    """Whether metrics `a` and `b` of one row agree in every figure the tables show."""
    cols = ["n_seeds", "final", "final_low", "final_high", "auc", "auc_low", "auc_high", "final_env_steps"]
    cols += ["evaluations", "evaluation_gap"]
    cols += [f"steps_to_{thr:g}" for thr in THRESHOLDS] + [f"seeds_reaching_{thr:g}" for thr in THRESHOLDS]
    return all(_equal(r[f"{a}_{c}"], r[f"{b}_{c}"]) for c in cols)


def _equal(x, y) -> bool:
    if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return True
    return bool(x == y)


def markdown(frame: pd.DataFrame) -> str:
    """summary.md: the headline table, then the details table."""
    return headline_table(frame).markdown() + "\n" + details_table(frame).markdown()


def _duration(seconds: float) -> str:
    if seconds is None or math.isnan(seconds):
        return "-"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.2f} h"


# ---------------------------------------------------------------------------------------------- P(X > Y)


ALSO_CONFIDENCE = 0.99  # the second reading beside each P: a Bonferroni-style bound for several comparisons


def improvement_frame(
    configs: list[ConfigSummary],
    reps: int = stats.DEFAULT_REPS,
    seed: int = 0,
    over: str = "best",
    reference: ConfigSummary | None = None,
) -> pd.DataFrame:
    """One row per pair (`improvement_pairs`: CO-PILOT's default, or the --reference configuration,
    against the best other or each other one): P(reference beats it) on final success and on the
    success AUC, from the seeds' scores (`stats.improvement`), with the reading of its 95 % CI and, beside
    it, of its 99 % CI (`_99` columns)."""
    metric = headline_metric(configs)
    rows = []
    for x, y in improvement_pairs(configs, metric, over, reference):
        mx, my = x.metrics[metric], y.metrics[metric]
        row: dict[str, object] = {"reference": x.label, "other": y.label, "metric": metric}
        # a privileged CO-PILOT (after_failure restart) is paired too: its privileges stay beside it
        row["reference_privileges"], row["other_privileges"] = x.privileges, y.privileges
        for what, a, b in (("final", mx.finals, my.finals), ("auc", mx.aucs, my.aucs)):
            imp = stats.improvement(a, b, reps=reps, seed=seed)
            row[f"p_{what}"] = imp.p  # (its interval only from MIN_SEEDS_FOR_CI seeds a side: NaN below)
            row[f"p_{what}_low"], row[f"p_{what}_high"] = imp.low, imp.high
            row[f"p_{what}_text"] = imp.text()
            row[f"p_{what}_reading"] = imp.reading()
            wide = stats.improvement(a, b, reps=reps, seed=seed, confidence=ALSO_CONFIDENCE)
            row[f"p_{what}_low_99"], row[f"p_{what}_high_99"] = wide.low, wide.high
            row[f"p_{what}_reading_99"] = wide.reading()
        row["final_ci_apart"] = ci_apart(mx.final, my.final)
        rows.append(row)
    return pd.DataFrame(rows)


def ci_apart(x: stats.SeedSummary, y: stats.SeedSummary) -> str:
    """Whether x's CI lies wholly above y's ("yes"), below it, or they overlap; without a CI on both
    sides (fewer than MIN_SEEDS_FOR_CI seeds) there is nothing to tell."""
    if not (x.has_ci and y.has_ci):
        return f"no CI (n = {x.n} and {y.n}; a CI needs {stats.MIN_SEEDS_FOR_CI})"
    if x.low > y.high:
        return f"yes: {x.low:.3f} > {y.high:.3f}"
    if x.high < y.low:
        return f"below: {x.high:.3f} < {y.low:.3f}"
    return f"no: they overlap ([{x.low:.3f}, {x.high:.3f}] and [{y.low:.3f}, {y.high:.3f}])"


def improvement_table(frame: pd.DataFrame, reference: bool = False) -> Table:
    """The P(X > Y) rows as the page shows them; `reference`: X was named by --reference (else it is
    CO-PILOT's default)."""
    who = "reference (--reference; privileges)" if reference else "CO-PILOT (default preset; privileges)"
    apart = (
        "final success CIs apart (the reference's above)"
        if reference
        else "final success CIs apart (CO-PILOT's above)"
    )
    table = Table(
        [
            who,
            "other (privileges)",
            "P(final success higher)",
            "reading (final; 99% CI)",
            "P(AUC higher)",
            "reading (AUC; 99% CI)",
            apart,
        ]
    )
    for _, r in frame.iterrows():
        table.rows.append(
            [
                f"{r['reference']} ({r['reference_privileges']})",
                f"{r['other']} ({r['other_privileges']})",
                str(r["p_final_text"]),
                _readings(r, "final"),
                str(r["p_auc_text"]),
                _readings(r, "auc"),
                str(r["final_ci_apart"]),
            ]
        )
    return table


def _readings(r, what: str) -> str:
    """The 95 % CI's reading, and the 99 % CI's beside it where there is one: "ahead (99%: not separated)"."""
    first, wide = str(r[f"p_{what}_reading"]), str(r.get(f"p_{what}_reading_99", ""))
    if not wide or wide.startswith("no reading"):
        return first
    return f"{first} (99%: {wide})"


def improvement_markdown(frame: pd.DataFrame) -> str:
    return improvement_table(frame).markdown()


# ---------------------------------------------------------------------------------------------- paired


PAIRED_FIGURES = (("final", "finals"), ("auc", "aucs"))  # (name, MetricSummary field): primary, secondary


def paired_frame(
    configs: list[ConfigSummary], over: str = "best", reference: ConfigSummary | None = None
) -> pd.DataFrame:
    """--paired: for each pair the probability of improvement compares (`improvement_pairs`), on final
    success (the primary figure) and on its AUC (the secondary), the per-seed differences reference -
    other over the seeds both have (seed for seed), the exact two-sided Wilcoxon signed-rank test over
    them (`stats.signed_rank_test`), and Holm's adjusted p over the tests of one figure (a family per
    figure: the comparisons made against the reference on final success, and those on its AUC, so that
    the primary figure's tests are corrected among themselves only, as a rule fixed before a run states
    them). The reading at alpha 0.05 on the adjusted p: "ahead" (the reference higher: W+ > W-),
    "behind", or "not separated". `warm_start`: whether the pair shares each seed's planner warm start
    (`warm_start_pairing`), the check that the seeds pair at all."""
    metric = headline_metric(configs)
    rows = []
    for x, y in improvement_pairs(configs, metric, over, reference):
        mx, my = x.metrics[metric], y.metrics[metric]
        for what, field_name in PAIRED_FIGURES:
            a = dict(zip(mx.seeds, getattr(mx, field_name), strict=True))
            b = dict(zip(my.seeds, getattr(my, field_name), strict=True))
            common = sorted(
                (s for s in a if s in b and np.isfinite(a[s]) and np.isfinite(b[s])), key=natural_key
            )
            diffs = np.array([a[s] - b[s] for s in common])
            test = stats.signed_rank_test(diffs)
            rows.append(
                {
                    "reference": x.label,
                    "other": y.label,
                    "metric": metric,
                    "figure": what,
                    "n_pairs": len(common),
                    "seeds": " ".join(str(s) for s in common),
                    "differences": "; ".join(f"{s}: {d:+.6g}" for s, d in zip(common, diffs, strict=True)),
                    "_differences": diffs.tolist(),  # the page rounds these, not the text above
                    "median_difference": float(np.median(diffs)) if len(diffs) else math.nan,
                    "zeros_dropped": test.zeros,
                    "w_plus": test.w_plus,
                    "w_minus": test.w_minus,
                    "W": test.statistic,
                    "p": test.p,
                    "p_method": test.method,
                    "unpaired_seeds": " ".join(str(s) for s in sorted(set(a) ^ set(b), key=natural_key)),
                    "warm_start": warm_start_pairing(x, y, common),
                }
            )
    frame = pd.DataFrame(rows)
    if frame.empty:
        return frame
    frame["p_holm"] = np.nan
    for _, family in frame.groupby("figure", sort=False):
        frame.loc[family.index, "p_holm"] = stats.holm(family["p"].to_numpy())
    frame["reading"] = [_paired_reading(r) for _, r in frame.iterrows()]
    return frame


WARM_START_SHARED = "shared"  # every common seed's warm start logged the same cost on both sides


def warm_start_pairing(x: ConfigSummary, y: ConfigSummary, seeds: list[str]) -> str:
    """Whether `x` and `y` share each seed's planner warm start: its logged cost
    (`PLANNER_WARM_START_COST`, the last warm-start phase's finest layer) equal, to the bit, seed for
    seed. CO-PILOT's rows that differ only after the warm start (a frozen or cost-blind planner) run the
    same warm start from the same seed, so a difference means the seeds do not pair (another commit, a
    changed planner setting). "shared"; "differs at seed s (a vs b), ..."; "not logged" (a row without
    a planner, or older runs)."""

    def costs(c: ConfigSummary) -> dict[str, float]:
        return {
            t.seed: t.latest[PLANNER_WARM_START_COST] for t in c.trials if PLANNER_WARM_START_COST in t.latest
        }

    a, b = costs(x), costs(y)
    if not seeds or any(s not in a or s not in b for s in seeds):
        return "not logged"
    differ = [f"seed {s} ({a[s]:.6g} vs {b[s]:.6g})" for s in seeds if a[s] != b[s]]
    return "differs at " + ", ".join(differ) if differ else WARM_START_SHARED


def _paired_reading(r) -> str:
    if r["n_pairs"] == 0:
        return "no test: no seed in common"
    if not np.isfinite(r["p_holm"]) or r["p_holm"] >= stats.PAIRED_ALPHA:
        return "not separated"
    return "ahead" if r["w_plus"] > r["w_minus"] else "behind"


def paired_table(frame: pd.DataFrame) -> Table:
    table = Table(
        [
            "reference",
            "other",
            "figure",
            "per-seed difference (reference - other)",
            "pairs (zeros dropped)",
            "W (W+, W-)",
            "p (exact, two-sided)",
            "Holm-adjusted p",
            f"reading (alpha {stats.PAIRED_ALPHA:g})",
            "warm start",
        ]
    )
    for _, r in frame.iterrows():
        seeds = str(r["seeds"]).split()
        diffs = "; ".join(f"{s}: {d:+.3f}" for s, d in zip(seeds, r["_differences"], strict=True))
        table.rows.append(
            [
                str(r["reference"]),
                str(r["other"]),
                str(r["figure"]),
                diffs or "-",
                f"{r['n_pairs']} ({r['zeros_dropped']})",
                "-" if not np.isfinite(r["W"]) else f"{r['W']:g} ({r['w_plus']:g}, {r['w_minus']:g})",
                _num(r["p"], ".4f"),
                _num(r["p_holm"], ".4f"),
                str(r["reading"]),
                str(r.get("warm_start", "not logged")),
            ]
        )
    return table
