"""Trials -> configurations: per-configuration curves, final success, the normalised area under the
success curve, steps-to-threshold, wall time, env steps and privileges aggregated over seeds, plus the
list of what is missing from the sweep.

Over seeds, every figure follows `stats.SeedSummary`: IQM and a 95 % bootstrap CI from
`stats.MIN_SEEDS_FOR_CI` seeds on, else the mean and the seeds' range. No "best over evaluations": a
maximum over noisy evaluations is biased upwards and rewards evaluating often.

Kept apart from `tables` and `figures` so that both draw from the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from copilot_ray.keys import (
    ALGORITHM_TAG,
    CURVE_METRICS,
    ENV_TAG,
    EVAL_SUCCESS,
    PRESET_TAG,
    PRIVILEGE_COUNTS,
    PRIVILEGES_TAG,
    SUCCESS_PLANNED,
    VARIANT_TAG,
)
from copilot_ray.privileges import from_tag
from copilot_ray.registry import UnknownAlgorithmError, get_algorithm

from . import stats
from .load import (
    CONFIG_KEY_AXIS,
    Sweep,
    Trial,
    axis_name,
    axis_value,
    configurations,
    is_env_axis,
    natural_key,
)

THRESHOLDS = (0.5, 0.9)
COPILOT = "copilot"  # the algorithm tag of CO-PILOT's runs
DEFAULT_PRESETS = ("default", "", "None")  # preset tag of a run without a preset
UNKNOWN = "-"  # privileges of runs older than the tag


@dataclass
class CurveSummary:
    """One metric of one configuration on the common env-step grid."""

    grid: np.ndarray
    center: np.ndarray  # IQM over seeds (>= MIN_SEEDS_FOR_CI seeds), else the mean
    low: np.ndarray  # the CI's bounds when `has_ci`, else the seeds' min and max
    high: np.ndarray
    coverage: np.ndarray  # seeds with data at each grid step
    n_seeds: int
    single_point: bool  # every seed has at most one evaluation: a marker, never a line
    point_step: float = float("nan")  # where to put that marker
    seed_curves: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # each seed's evaluations

    @property
    def has_ci(self) -> bool:
        return stats.has_ci(self.n_seeds)


@dataclass
class MetricSummary:
    n_seeds: int  # seeds with at least one evaluation of this metric
    # each seed's final (`final_values`: its success at the budget, or the mean of its last K evaluations
    # at or before it); NaN: a seed with fewer than K such evaluations
    finals: np.ndarray
    final: stats.SeedSummary
    aucs: np.ndarray  # each seed's normalised area under the curve over `auc_window` (NaN: not covered)
    auc: stats.SeedSummary
    auc_window: tuple[float, float]  # env steps, the same for every configuration
    final_step: float  # mean over seeds of the env step each final is read at (the budget if reached)
    # mean over seeds of the evaluations up to the budget, and of the median env steps between two
    # (through the first evaluation past the budget): the cadence a curve and its final rest on
    evaluations: float
    evaluation_gap: float
    # threshold -> (IQM, or mean with fewer than 5 seeds, of steps to reach it, inf = not reached;
    # seeds that reached it)
    to_threshold: dict[float, tuple[float, int]]
    curve: CurveSummary | None
    final_evaluations: int | None = None  # K of `final_values` (None: the curve at the budget)
    seeds: list[str] = field(default_factory=list)  # each value's seed, in the order of `finals` and `aucs`


def follows_plan(algorithm: str) -> bool | None:
    """Whether `algorithm`'s evaluation follows a plan, its agent alone logged apart: it declares the
    planned success among its metrics. None for an algorithm this checkout does not have."""
    try:
        return SUCCESS_PLANNED in get_algorithm(algorithm).metrics
    except UnknownAlgorithmError:
        return None


@dataclass
class ConfigSummary:
    key: str  # copilot.config_key
    label: str  # what the varying axes say about it, e.g. "K=3"
    trials: list[Trial]  # the usable trials with evaluations (what the numbers are computed from)
    all_trials: list[Trial]
    metrics: dict[str, MetricSummary]
    wall_time_s: float  # mean over seeds of the last `time_total_s`
    env_steps: float = float("nan")  # mean over seeds of the env steps at the last result
    # privilege counter key -> mean over seeds of its final (cumulative) count; NaN: not logged
    privilege_counts: dict[str, float] = field(default_factory=dict)
    privileges: str = UNKNOWN  # the names from the tag, "none", or "-" (runs older than the tag)
    env: str = (
        ""  # the env it ran on: its id and the env-config values that vary ("maze-point, layout=u-maze")
    )
    method: str = ""  # the label without the env's axes, led by the algorithm ("copilot (variant=continue)")

    @property
    def env_id(self) -> str:
        return self.all_trials[0].env_id

    @property
    def n_seeds(self) -> int:
        return len(self.trials)

    @property
    def algorithm(self) -> str:
        return self.all_trials[0].tags.get(ALGORITHM_TAG, "")

    @property
    def is_copilot_default(self) -> bool:
        """CO-PILOT with its default settings (no preset): the configuration the paper's claims are about."""
        return self.algorithm == COPILOT and self.all_trials[0].tags.get(PRESET_TAG, "") in DEFAULT_PRESETS


@dataclass
class Missing:
    failed: list[Trial] = field(default_factory=list)  # FAILED / KILLED: excluded from the numbers
    running: list[Trial] = field(default_factory=list)  # included, but their values are provisional
    no_eval: list[Trial] = field(default_factory=list)  # usable runs without any evaluation metric
    # (label, missing seeds, whether another configuration has them with evaluations)
    short_configs: list[tuple[str, list[str], bool]] = field(default_factory=list)
    single_point: list[tuple[str, str]] = field(default_factory=list)  # (label, metric)
    # (label, seed, evaluations it has at or before the budget, K): too few for --final-evaluations K
    short_finals: list[tuple[str, str, int, int]] = field(default_factory=list)

    def empty(self) -> bool:
        return not (
            self.failed
            or self.running
            or self.no_eval
            or self.short_configs
            or self.single_point
            or self.short_finals
        )

    def lines(self) -> list[str]:
        out = []
        for t in self.failed:
            out.append(
                f"{t.status.lower()} run {t.run_name} ({t.run_id}): config {t.config_key}, seed {t.seed} "
                "- excluded from all numbers"
            )
        for t in self.running:
            out.append(
                f"still running: {t.run_name} ({t.run_id}): config {t.config_key}, seed {t.seed} "
                "- included; its final values are provisional"
            )
        for t in self.no_eval:
            out.append(
                f"no evaluation metrics yet ({t.status.lower()}): {t.run_name} ({t.run_id}): config {t.config_key}, seed {t.seed}"
            )
        for label, seeds, elsewhere in self.short_configs:
            # "than the others" only where there are others that have them: one configuration of an
            # interrupted sweep lacks seeds whose own runs failed or have not evaluated yet
            why = (
                "fewer seeds than the others"
                if elsewhere
                else "its runs of them ended unfinished or have no evaluation yet, as listed here"
            )
            out.append(f"configuration {label} lacks seeds {', '.join(seeds)} ({why})")
        for label, seed, have, k in self.short_finals:
            out.append(
                f"configuration {label}, seed {seed}: {have} evaluation(s) due at or before the budget, fewer "
                f"than --final-evaluations {k}: no final success (left out of the final's figures)"
            )
        for label, metric in self.single_point:
            out.append(
                f"configuration {label}: {metric} has a single evaluation - drawn as a marker, not a trend"
            )
        return out


def config_label(trial: Trial, axes: list[str]) -> str:
    """What the varying axes say about a trial's configuration: "layout=u-maze, variant=continue"; the config
    key itself for the config-key axis."""
    return ", ".join(_label_parts(trial, axes)) or trial.config_key


def _label_parts(trial: Trial, axes: list[str]) -> list[str]:
    parts = []
    for a in axes:
        value = axis_value(trial, a)
        if a == CONFIG_KEY_AXIS:
            parts.append(value)
        # An axis the trial's algorithm does not have (K of a baseline; "None" or empty) is left out.
        elif value not in ("None", ""):
            parts.append(f"{axis_name(a)}={value}")
    return parts


def env_label(trial: Trial, axes: list[str]) -> str:
    """The env a trial ran on: its id and the env-config values that vary between configurations."""
    env_config = [a for a in axes if is_env_axis(a) and a != ENV_TAG]
    return ", ".join([trial.env_id or "?", *_label_parts(trial, env_config)])


def method_label(trial: Trial, axes: list[str]) -> str:
    """The label without the env's axes, led by the algorithm: "rrt_star", "copilot (variant=continue)"."""
    rest = _label_parts(trial, [a for a in axes if not is_env_axis(a) and a != ALGORITHM_TAG])
    algorithm = trial.tags.get(ALGORITHM_TAG, "") or "?"
    return f"{algorithm} ({', '.join(rest)})" if rest else algorithm


def summarise(
    sweep: Sweep, reps: int = stats.DEFAULT_REPS, seed: int = 0, final_evaluations: int | None = None
) -> tuple[list[ConfigSummary], Missing]:
    """Every configuration's figures over its seeds, and what is missing. `final_evaluations` K: each
    seed's final is the mean of its last K evaluations at or before the budget (`final_values`); None:
    its curve at the budget."""
    if final_evaluations is not None and final_evaluations < 1:
        raise ValueError(f"final_evaluations={final_evaluations!r} is invalid: an integer >= 1")
    axes = sweep.axes()
    missing = Missing()
    by_key = _keyed(configurations(sweep.trials), axes)
    for t in sweep.trials:
        if not t.usable:
            missing.failed.append(t)
        else:
            if not t.has_eval:
                missing.no_eval.append(t)
            elif t.status == "RUNNING":
                missing.running.append(t)

    included = [t for t in sweep.trials if t.usable and t.has_eval]
    budget = common_budget(included)
    # Curves end at the budget, where the finals are read: a method whose last iteration ran past it
    # (by up to one iteration) is not drawn further than the others.
    grids = {
        m: _grid_to(stats.common_grid([t.curves[m][0] for t in included if m in t.curves]), budget)
        for m in CURVE_METRICS
    }
    # The AUC window is set by the finished seeds (they ran to the budget): a running one must not cut
    # everyone's window short; it gets an AUC once it covers the window.
    finished = [t for t in included if t.status == "FINISHED"] or included
    windows = {
        m: _capped(stats.auc_window([t.curves[m][0] for t in finished if m in t.curves]), budget)
        for m in CURVE_METRICS
    }
    all_seeds = sorted({t.seed for t in sweep.trials}, key=natural_key)
    # the evaluations a count is read at: those the final success is read from (`_count_at`)
    headline = EVAL_SUCCESS if any(EVAL_SUCCESS in t.curves for t in included) else SUCCESS_PLANNED

    configs = []
    for key, trials in by_key.items():
        use = [t for t in trials if t.usable and t.has_eval]
        label = config_label(trials[0], axes)
        have = {t.seed for t in use}
        lacking = [s for s in all_seeds if s not in have]
        if lacking:
            mine = {t.run_id for t in trials}
            elsewhere = {t.seed for t in included if t.run_id not in mine}  # other configurations'
            missing.short_configs.append((label, lacking, any(s in elsewhere for s in lacking)))
        metrics = {}
        for m in CURVE_METRICS:
            with_m = [t for t in use if m in t.curves]
            ms = _metric_summary(with_m, m, grids[m], windows[m], budget, reps, seed, final_evaluations)
            if ms is not None:
                metrics[m] = ms
                if ms.curve is not None and ms.curve.single_point:
                    missing.single_point.append((label, m))
                if m == headline and final_evaluations is not None:
                    for t, f in zip(with_m, ms.finals, strict=True):
                        if np.isnan(f):
                            n = evaluations_up_to(t.curves[m][0], budget, t.eval_every)
                            missing.short_finals.append((label, t.seed, n, final_evaluations))
        walls = [t.wall_time_s for t in use if np.isfinite(t.wall_time_s)]
        configs.append(
            ConfigSummary(
                key=key,
                label=label,
                trials=use,
                all_trials=trials,
                metrics=metrics,
                wall_time_s=float(np.mean(walls)) if walls else float("nan"),
                env_steps=_mean([t.env_steps for t in use]),
                privilege_counts={
                    k: _mean([_count_at(t, k, budget, headline, final_evaluations) for t in use])
                    for k in PRIVILEGE_COUNTS
                },
                privileges=privileges_label(trials),
                env=env_label(trials[0], axes),
                method=method_label(trials[0], axes),
            )
        )
    configs.sort(key=lambda c: _config_order(c, axes))
    return configs, missing


def _keyed(groups: dict[tuple, list[Trial]], axes: list[str]) -> dict[str, list[Trial]]:
    """Each configuration under a unique key: its config key; led by the algorithm when several share
    config keys (a several-spec file: "env.id=maze-point"); followed by its label when that is still not
    unique (one config key on two layouts, or in two sweeps)."""
    several = len({g[0].tags.get(ALGORITHM_TAG, "") for g in groups.values()}) > 1

    def base(t: Trial) -> str:
        return f"{t.tags.get(ALGORITHM_TAG, '?')}: {t.config_key}" if several else t.config_key

    counts: dict[str, int] = {}
    for g in groups.values():
        counts[base(g[0])] = counts.get(base(g[0]), 0) + 1
    out: dict[str, list[Trial]] = {}
    for g in groups.values():
        key = base(g[0])
        if counts[key] > 1:
            key = f"{key} [{config_label(g[0], axes)}]"
        while key in out:  # labels that still collide (no axis tells them apart): numbered
            key += "'"
        out[key] = g
    return out


def _config_order(c: ConfigSummary, axes: list[str]):
    # Numeric axes (K, b) sort numerically so Fig. 2b reads K = 1, 2, ..., 10, not 1, 10, 2.
    t = c.all_trials[0]
    return tuple(natural_key(axis_value(t, a) if a != CONFIG_KEY_AXIS else c.key) for a in axes) + (c.key,)


def _mean(values) -> float:
    """Mean over seeds of the values they have; NaN when none has one (not logged)."""
    finite = [float(v) for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def privileges_label(trials: list[Trial]) -> str:
    """What a configuration's privilege tags say: names joined by ", ", "none", or "-" (not tagged);
    several different tags (which one configuration should not have) are all shown, " / "-separated."""
    labels = []
    for t in trials:
        tag = t.tags.get(PRIVILEGES_TAG)
        label = UNKNOWN if tag is None else ", ".join(from_tag(tag)) or "none"
        if label not in labels:
            labels.append(label)
    return " / ".join(labels) or UNKNOWN


def headline_metric(configs: list[ConfigSummary]) -> str:
    """The success every method reports (copilot/eval/success); older CO-PILOT runs: success_planned."""
    return EVAL_SUCCESS if any(EVAL_SUCCESS in c.metrics for c in configs) else SUCCESS_PLANNED


IMPROVEMENT_OVER = ("best", "each")


def improvement_pairs(
    configs: list[ConfigSummary], metric: str, over: str = "best", reference: ConfigSummary | None = None
) -> list[tuple[ConfigSummary, ConfigSummary]]:
    """(X, other) pairs for P(X > other). Without `reference`, X is each CO-PILOT default configuration
    with `metric`; over="best": the other is the configuration of another algorithm with the highest
    final `metric` (IQM, or mean with fewer than 5 seeds); over="each": every other configuration,
    CO-PILOT's own variants (an ablation) included. With `reference` (--reference, e.g. one depth of a
    depth sweep, where every row is CO-PILOT), X is that configuration alone; "best": the other
    configuration with the highest final `metric`, "each": every other one. [] without such a pair (e.g.
    a sweep of one algorithm and no reference)."""
    if over not in IMPROVEMENT_OVER:
        raise ValueError(f"over={over!r} is invalid: use one of {IMPROVEMENT_OVER}")
    if reference is not None:
        if metric not in reference.metrics:
            return []
        others = [c for c in configs if c is not reference and metric in c.metrics]
        if over == "each" or not others:
            return [(reference, y) for y in others]
        return [(reference, max(others, key=lambda c: _final_point(c, metric)))]
    defaults = [c for c in configs if c.is_copilot_default and metric in c.metrics]
    if over == "each":
        # CO-PILOT's default as it ships: a variant of it (an ablation, a privileged row) is an other.
        plain = [c for c in defaults if not c.all_trials[0].tags.get(VARIANT_TAG)] or defaults
        return [(x, y) for x in plain for y in configs if y is not x and metric in y.metrics]
    others = [c for c in configs if c.algorithm != COPILOT and metric in c.metrics]
    if not others:
        return []
    best = max(others, key=lambda c: _final_point(c, metric))
    return [(c, best) for c in defaults]


def _final_point(c: ConfigSummary, metric: str) -> float:
    return float(np.nan_to_num(c.metrics[metric].final.point, nan=-np.inf))


class UnknownConfigurationError(ValueError):
    """A configuration named (--reference) that the report does not have, or that names several."""


def find_configuration(configs: list[ConfigSummary], name: str) -> ConfigSummary:
    """The configuration `name` names, as the report labels it: its label ("K=5", "algorithm=copilot,
    variant=frozen_planner, K=5"), its config key ("tree_depth=5"), its variant's name
    ("frozen_planner"), or some of its label's parts ("variant=frozen_planner"); the first of these rules
    that names exactly one wins. UnknownConfigurationError, listing the labels there are, when none names
    one, or one names several."""
    wanted = [part.strip() for part in name.split(",") if part.strip()]
    rules = (
        lambda c: c.label == name,
        lambda c: c.key == name or any(t.config_key == name for t in c.all_trials),
        lambda c: c.all_trials[0].tags.get(VARIANT_TAG, "") == name,
        lambda c: bool(wanted) and set(wanted) <= {p.strip() for p in c.label.split(",")},
    )
    labels = "; ".join(repr(c.label) for c in configs) or "(none)"
    for rule in rules:
        found = [c for c in configs if rule(c)]
        if len(found) == 1:
            return found[0]
        if found:
            raise UnknownConfigurationError(
                f"{name!r} names {len(found)} configurations: "
                + "; ".join(repr(c.label) for c in found)
                + " (give more of the label)"
            )
    raise UnknownConfigurationError(f"{name!r} is no configuration here; the labels are: {labels}")


def _metric_summary(
    trials,
    metric: str,
    grid: np.ndarray,
    window,
    budget: float,
    reps: int,
    seed: int,
    final_evaluations: int | None = None,
):
    if not trials:
        return None
    finals, final_steps = final_values(trials, metric, budget, final_evaluations)
    aucs = np.array([stats.normalised_auc(*t.curves[metric], *window) for t in trials])
    to_thr = {}
    for thr in THRESHOLDS:
        s = np.array([stats.steps_to_threshold(*t.curves[metric], thr) for t in trials])
        to_thr[thr] = (float(stats.center(s)), int(np.isfinite(s).sum()))
    return MetricSummary(
        n_seeds=len(trials),
        finals=finals,
        final=stats.summarise_seeds(finals, reps=reps, seed=seed),
        aucs=aucs,
        auc=stats.summarise_seeds(aucs, reps=reps, seed=seed),
        auc_window=window,
        final_step=_mean(final_steps),
        **_cadence(trials, metric, budget),
        to_threshold=to_thr,
        curve=_curve(trials, metric, grid, reps, seed),
        final_evaluations=final_evaluations,
        seeds=[t.seed for t in trials],
    )


def _grid_to(grid: np.ndarray, budget: float) -> np.ndarray:
    """`grid` up to `budget`, the budget itself its last point where the grid passed it."""
    if not np.isfinite(budget) or grid.size == 0 or grid[-1] <= budget:
        return grid
    kept = grid[grid <= budget]
    return np.append(kept, budget) if kept.size else grid[:1]


def _count_at(
    t: Trial, key: str, budget: float, metric: str = EVAL_SUCCESS, final_evaluations: int | None = None
) -> float:
    """A privilege count (cumulative) where the trial's final `metric` is read: at the evaluations the
    final is a weighted mean of, with the same weights (`final_reading`), so that success and count come
    from the same point. A count spent inside evaluations (SoRB with the map checks at each evaluation)
    thus includes the evaluation the final is read from, and no later one. Without that curve: the count
    interpolated at the budget where the run went past it, its last value otherwise."""
    if key in t.curves and metric in t.curves:
        steps, values = t.curves[metric]
        index, weights, _ = final_reading(steps, budget, final_evaluations, t.eval_every)
        if len(index):
            counts = np.interp(steps[index], *t.curves[key])
            return float(np.dot(counts, weights))
    if key in t.curves and np.isfinite(budget):
        steps, values = t.curves[key]
        if len(steps) and steps[-1] > budget:
            return float(np.interp(budget, steps, values))
    return t.latest.get(key, np.nan)


def common_budget(trials: list[Trial]) -> float:
    """The env-step budget every trial's sweep had (the smallest, should they differ); NaN when a
    trial's sweep had none (stopped by iterations, or runs older than the param)."""
    budgets = [t.budget for t in trials]
    return float(min(budgets)) if budgets and all(np.isfinite(budgets)) else float("nan")


def _capped(window: tuple[float, float], budget: float) -> tuple[float, float]:
    """The AUC window ending at the budget at the latest: experience past it is not scored."""
    start, end = window
    if np.isfinite(budget) and np.isfinite(end) and end > budget:
        end = budget
    return (start, end) if np.isfinite(end) and end > start else (np.nan, np.nan)


def final_values(
    trials: list[Trial], metric: str, budget: float, final_evaluations: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Each seed's final success and the env step it is read at.

    By default (`final_evaluations` None) its curve at the env-step budget, linear between the
    evaluations on either side; a seed whose evaluations end before the budget (still running) gives its
    last one, one whose evaluations all come after it its first; a sweep without a budget: the last
    evaluation. Why not simply the last evaluation: a trial stops at the end of the first iteration past
    the budget, so a method with long iterations (CO-PILOT's are ~16k env steps) would be scored after up
    to an iteration more experience than one with short iterations.

    With `final_evaluations` K (a rule fixed in advance, e.g. docs/depth_k): the mean of the seed's last
    K evaluations at or before the budget (`evaluations_up_to`: an evaluation counts at the cadence point
    it was due at), read at the last of them; a seed with fewer than K there has none (NaN, NaN). See
    `final_reading`.
    """
    read = [value_at(t.curves[metric], budget, final_evaluations, t.eval_every) for t in trials]
    return np.array([v for v, _ in read]), np.array([at for _, at in read])


def final_reading(
    steps: np.ndarray, budget: float, final_evaluations: int | None = None, every: float = float("nan")
) -> tuple[np.ndarray, np.ndarray, float]:
    """Which evaluations a curve's final is read from: (their indices into `steps`, sorted; weights
    summing to 1; the env step it is read at). `final_values`' rule: at the budget, the one or two
    evaluations on either side with linear weights; with K, the last K at or before it
    (`evaluations_up_to`, on the cadence `every`), 1/K each. Empty (and NaN) where there is none."""
    steps = np.asarray(steps, dtype=np.float64)
    none = (np.zeros(0, dtype=np.int64), np.zeros(0), float("nan"))
    if not len(steps):
        return none
    if final_evaluations is not None:
        upto = evaluations_up_to(steps, budget, every)
        if upto < final_evaluations:
            return none
        index = np.arange(upto - final_evaluations, upto)
        return index, np.full(final_evaluations, 1.0 / final_evaluations), float(steps[upto - 1])
    at = float(np.clip(budget, steps[0], steps[-1])) if np.isfinite(budget) else float(steps[-1])
    j = int(np.searchsorted(steps, at, side="left"))  # the first evaluation at or after it
    if steps[j] == at or j == 0:
        return np.array([j]), np.array([1.0]), at
    w = (at - steps[j - 1]) / (steps[j] - steps[j - 1])
    return np.array([j - 1, j]), np.array([1.0 - w, w]), at


def evaluations_up_to(steps: np.ndarray, budget: float, every: float = float("nan")) -> int:
    """How many of a curve's evaluations are at or before the budget (all of them without one). With an
    env-step cadence `every` (`Trial.eval_every`), an evaluation counts at the cadence point it was due
    at, floor(env steps / every) x every: an evaluation runs at the end of the first iteration past its
    point, so the one due at a 200k budget runs a little after it (the privilege-matched runs': 200,010
    to 202,027 env steps) and is the evaluation "at 200k"; without a cadence, at its own env step."""
    steps = np.asarray(steps, dtype=np.float64)
    if not np.isfinite(budget):
        return len(steps)
    due = np.floor(steps / every) * every if np.isfinite(every) and every > 0 else steps
    return int((due <= budget).sum())


def value_at(
    curve: tuple[np.ndarray, np.ndarray],
    budget: float,
    final_evaluations: int | None = None,
    every: float = float("nan"),
) -> tuple[float, float]:
    """A curve's final and the env step it is read at (`final_values`' rule); (NaN, NaN) for an empty
    curve, or with `final_evaluations` K one with fewer than K evaluations at or before the budget."""
    steps, values = curve
    index, weights, at = final_reading(steps, budget, final_evaluations, every)
    if not len(index):
        return float("nan"), float("nan")
    return float(np.dot(np.asarray(values, dtype=np.float64)[index], weights)), at


def final_words(final_evaluations: int | None) -> str:
    """What "final" means on the page, in a few words (a figure's axis, a table's note)."""
    if final_evaluations is None:
        return "at the env-step budget"
    if final_evaluations == 1:
        return "the last evaluation due at or before the budget"
    return f"mean of the last {final_evaluations} evaluations due at or before the budget"


def _cadence(trials: list[Trial], metric: str, budget: float) -> dict[str, float]:
    """`MetricSummary.evaluations` and `.evaluation_gap`: methods of one comparison should be evaluated
    on one env-step cadence, and the report shows where they were not."""
    counts, gaps = [], []
    for t in trials:
        s = np.asarray(t.curves[metric][0], dtype=float)
        if np.isfinite(budget):
            counts.append(int((s <= budget).sum()))
            s = s[: int(np.searchsorted(s, budget, side="left")) + 1]  # through the first at/after it
        else:
            counts.append(len(s))
        if len(s) > 1:
            gaps.append(float(np.median(np.diff(s))))
    return {"evaluations": float(np.mean(counts)), "evaluation_gap": _mean(gaps)}


def _curve(trials: list[Trial], metric: str, grid: np.ndarray, reps: int, seed: int) -> CurveSummary:
    n = len(trials)
    seed_curves = [t.curves[metric] for t in trials]
    if max(len(steps) for steps, _ in seed_curves) <= 1:
        # One evaluation per seed: the aggregate is a point (with a CI from 5 seeds on).
        values = np.array([values[0] for _, values in seed_curves])
        s = stats.summarise_seeds(values, reps=reps, seed=seed)
        return CurveSummary(
            grid=np.zeros(0),
            center=np.atleast_1d(s.point),
            low=np.atleast_1d(s.low),
            high=np.atleast_1d(s.high),
            coverage=np.array([n]),
            n_seeds=n,
            single_point=True,
            point_step=float(np.median([steps[0] for steps, _ in seed_curves])),
            seed_curves=seed_curves,
        )
    mat = np.stack([stats.interpolate(*c, grid) for c in seed_curves])  # [n_seeds, G]
    if stats.has_ci(n):
        low, high = stats.bootstrap_ci(mat, reps=reps, seed=seed)
    else:
        with stats.quiet_all_nan():  # columns no seed reached: NaN is right
            low, high = np.nanmin(mat, axis=0), np.nanmax(mat, axis=0)
    return CurveSummary(
        grid=grid,
        center=stats.center(mat, n),
        low=low,
        high=high,
        coverage=(~np.isnan(mat)).sum(axis=0),
        n_seeds=n,
        single_point=False,
        seed_curves=seed_curves,
    )
