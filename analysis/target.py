"""Whether CO-PILOT's default reaches a stated success, by how much it falls short, and what its
diagnostics say at the budget (`analysis.report --target`).

A comparison states its claim before it runs (e.g. "CO-PILOT's default reaches 0.6 final test success,
IQM over 5 seeds, with its CI's lower end above the best other method's upper end"). The verdict reads
the report's own figures, so it can neither pick a friendlier statistic nor hide a shortfall: each part
of the claim is met, short by a stated amount, or cannot be judged (too few seeds for an IQM or a CI).
The diagnostics table gives the figures the diagnostics figure draws as curves, each seed's value at
the env-step budget, so that a shortfall comes with the numbers that say where it comes from.
"""

from __future__ import annotations

import numpy as np

from copilot_ray.keys import (
    AGENT_SUBTASK_SUCCESS_LAYER,
    DIAG_SEGMENT_UNREACHABLE_LAYER,
    DIAG_SUBGOAL_IN_OBSTACLE_LAYER,
    DIAG_SUCCESS_AFTER_FAILED,
    DIAG_SUCCESS_AFTER_REACHED,
    PLANNED_COLLISION_FREE,
    REACHED_PLANNED,
    SUCCESS_DIRECT,
)

from . import stats
from .aggregate import ConfigSummary, common_budget, headline_metric, improvement_pairs, value_at
from .run_figures import depth_of
from .tables import Table

# (column, metric key; "{K}" is the run's finest tree layer). Evaluation figures first (on the report's
# task set: a validation report holds their validation twins), then the training traversals'.
DIAGNOSTIC_FIGURES = (
    ("plans collision-free", PLANNED_COLLISION_FREE),
    ("goal reached along the plan, collisions allowed", REACHED_PLANNED),
    ("agent alone (no plan)", SUCCESS_DIRECT),
    ("training sub-task success, layer K", AGENT_SUBTASK_SUCCESS_LAYER + "{K}"),
    ("sub-task success after a reached one", DIAG_SUCCESS_AFTER_REACHED),
    ("after a missed one", DIAG_SUCCESS_AFTER_FAILED),
    ("new sub-goals inside obstacles, layer K", DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "{K}"),
    ("segments longer than one sub-task reaches, layer K", DIAG_SEGMENT_UNREACHABLE_LAYER + "{K}"),
)


def diagnosed(configs: list[ConfigSummary]) -> list[ConfigSummary]:
    """The configurations whose runs logged sub-goal tree diagnostics (CO-PILOT's)."""
    return [c for c in configs if any(depth_of(t) > 0 for t in c.trials)]


def diagnostics_table(
    configs: list[ConfigSummary], reps: int = stats.DEFAULT_REPS, seed: int = 0
) -> Table | None:
    """One row per diagnosed configuration, one column per diagnostic figure some run logged: its seeds'
    values at the env-step budget (`cell`). None: nothing diagnosed."""
    shown = diagnosed(configs)
    if not shown:
        return None
    budget = common_budget([t for c in configs for t in c.trials])
    columns = {what: [] for what, _ in DIAGNOSTIC_FIGURES}
    for c in shown:
        for what, key in DIAGNOSTIC_FIGURES:
            values = []
            for t in c.trials:
                name = key.format(K=depth_of(t))
                values.append(value_at(t.curves[name], budget)[0] if name in t.curves else float("nan"))
            columns[what].append(cell(stats.summarise_seeds(np.array(values), reps=reps, seed=seed)))
    logged = [what for what, cells in columns.items() if any(x != "-" for x in cells)]
    table = Table(["configuration", *logged])
    for i, c in enumerate(shown):
        table.rows.append([c.label, *(columns[what][i] for what in logged)])
    return table


def cell(s: stats.SeedSummary) -> str:
    """A figure over seeds, short enough for a table of many columns: IQM [CI] from 5 seeds on, else the
    mean (the seeds' range, n); '-': no seed logged it."""
    if s.n == 0 or not np.isfinite(s.point):
        return "-"
    if s.has_ci:
        return f"{s.point:.2f} [CI {s.low:.2f}, {s.high:.2f}]"
    return f"{s.point:.2f}" + (f" ({s.low:.2f}-{s.high:.2f}, n = {s.n})" if s.n > 1 else " (n = 1)")


def verdict(configs: list[ConfigSummary], target: float, tasks: str) -> list[str]:
    """The claim "CO-PILOT's default reaches `target` final success (IQM over >= 5 seeds) and its CI lies
    above the best other method's", judged part by part for each CO-PILOT default configuration."""
    metric = headline_metric(configs)
    pairs = improvement_pairs(configs, metric)
    if not pairs:
        return [f"Nothing to judge: no CO-PILOT default configuration with {metric} beside another method's."]
    lines = []
    for x, best in pairs:
        mine, theirs = x.metrics[metric].final, best.metrics[metric].final
        lines.append(f"{x.label}: final {tasks} success {mine.text()}; " + _level(mine, target))
        lines.append(
            f"against the best other method, {best.label} ({theirs.text()}): " + _apart(mine, theirs)
        )
        if (direct := x.metrics.get(SUCCESS_DIRECT)) is not None and metric != SUCCESS_DIRECT:
            lines.append(f"{x.label}'s agent alone (no plan): final {tasks} success {direct.final.text()}.")
    return lines


def _level(s: stats.SeedSummary, target: float) -> str:
    if s.n == 0 or not np.isfinite(s.point):
        return f"target {target:g}: no final success to judge."
    if not s.has_ci:
        return (
            f"target {target:g} (an IQM over >= {stats.MIN_SEEDS_FOR_CI} seeds): cannot be judged on "
            f"{s.n} seed(s); their mean is {_gap(s.point, target)}."
        )
    return (
        f"target {target:g}: "
        + ("met" if s.point >= target else "NOT met")
        + f", the IQM is {_gap(s.point, target)}."
    )


def _gap(value: float, target: float) -> str:
    if value >= target:
        return f"{value - target:.3f} above it"
    return f"{target - value:.3f} short of it ({value / target:.0%} of the target)"


def _apart(mine: stats.SeedSummary, theirs: stats.SeedSummary) -> str:
    if not (mine.has_ci and theirs.has_ci):
        return (
            f"CIs apart cannot be judged (n = {mine.n} and {theirs.n}; a CI needs {stats.MIN_SEEDS_FOR_CI})."
        )
    if mine.low > theirs.high:
        return f"met: the lower end of its CI, {mine.low:.3f}, is {mine.low - theirs.high:.3f} above their upper end, {theirs.high:.3f}."
    return (
        f"NOT met: the lower end of its CI, {mine.low:.3f}, is {theirs.high - mine.low:.3f} short of their "
        f"upper end, {theirs.high:.3f}."
    )
