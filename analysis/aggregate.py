"""Trials -> configurations: per-configuration curves, final success, steps-to-threshold and wall time
aggregated over seeds, plus the list of what is missing from the sweep.

Kept apart from `tables` and `figures` so that both draw from the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from copilot_ray.keys import ALGORITHM_TAG, CURVE_METRICS

from . import stats
from .load import CONFIG_KEY_AXIS, Sweep, Trial, natural_key

THRESHOLDS = (0.5, 0.9)


@dataclass
class CurveSummary:
    """One metric of one configuration on the common env-step grid."""

    grid: np.ndarray
    iqm: np.ndarray
    low: np.ndarray
    high: np.ndarray
    coverage: np.ndarray  # seeds with data at each grid step
    n_seeds: int
    single_point: bool  # every seed has at most one evaluation: a marker, never a line
    point_step: float = float("nan")  # where to put that marker


@dataclass
class MetricSummary:
    n_seeds: int  # seeds with at least one evaluation of this metric
    final_iqm: float
    final_low: float
    final_high: float
    final_step: float  # IQM over seeds of the step of each seed's last evaluation
    # threshold -> (IQM over seeds of steps to reach it, inf = not reached; seeds that reached it)
    to_threshold: dict[float, tuple[float, int]]
    curve: CurveSummary | None


@dataclass
class ConfigSummary:
    key: str  # copilot.config_key
    label: str  # what the varying axes say about it, e.g. "K=3"
    trials: list[Trial]  # the usable trials with evaluations (what the numbers are computed from)
    all_trials: list[Trial]
    metrics: dict[str, MetricSummary]
    wall_time_s: float  # mean over seeds of the last `time_total_s`

    @property
    def n_seeds(self) -> int:
        return len(self.trials)


@dataclass
class Missing:
    failed: list[Trial] = field(default_factory=list)  # FAILED / KILLED: excluded from the numbers
    running: list[Trial] = field(default_factory=list)  # included, but their values are provisional
    no_eval: list[Trial] = field(default_factory=list)  # usable runs without any evaluation metric
    short_configs: list[tuple[str, list[str]]] = field(default_factory=list)  # (label, missing seeds)
    single_point: list[tuple[str, str]] = field(default_factory=list)  # (label, metric)

    def empty(self) -> bool:
        return not (self.failed or self.running or self.no_eval or self.short_configs or self.single_point)

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
        for label, seeds in self.short_configs:
            out.append(f"configuration {label} lacks seeds {', '.join(seeds)} (fewer seeds than the others)")
        for label, metric in self.single_point:
            out.append(
                f"configuration {label}: {metric} has a single evaluation - drawn as a marker, not a trend"
            )
        return out


def config_label(trial: Trial, axes: list[str]) -> str:
    if not axes:
        return trial.config_key
    if axes == [CONFIG_KEY_AXIS]:
        return trial.config_key
    # An axis the trial's algorithm does not have (K of a baseline; "None" or empty) is left out.
    parts = [f"{a}={trial.tags[a]}" for a in axes if trial.tags.get(a, "None") not in ("None", "")]
    return ", ".join(parts) or trial.config_key


def summarise(
    sweep: Sweep, reps: int = stats.DEFAULT_REPS, seed: int = 0
) -> tuple[list[ConfigSummary], Missing]:
    axes = sweep.axes()
    missing = Missing()
    by_key: dict[str, list[Trial]] = {}
    # Several algorithms (a several-spec file) may share config keys ("env.id=maze-point"): tell them apart.
    several = len({t.tags.get(ALGORITHM_TAG, "") for t in sweep.trials}) > 1
    for t in sweep.trials:
        key = f"{t.tags.get(ALGORITHM_TAG, '?')}: {t.config_key}" if several else t.config_key
        by_key.setdefault(key, []).append(t)
        if not t.usable:
            missing.failed.append(t)
        else:
            if not t.has_eval:
                missing.no_eval.append(t)
            elif t.status == "RUNNING":
                missing.running.append(t)

    included = [t for t in sweep.trials if t.usable and t.has_eval]
    grids = {m: stats.common_grid([t.curves[m][0] for t in included if m in t.curves]) for m in CURVE_METRICS}
    all_seeds = sorted({t.seed for t in sweep.trials}, key=natural_key)

    configs = []
    for key, trials in by_key.items():
        use = [t for t in trials if t.usable and t.has_eval]
        label = config_label(trials[0], axes)
        have = {t.seed for t in use}
        lacking = [s for s in all_seeds if s not in have]
        if lacking:
            missing.short_configs.append((label, lacking))
        metrics = {}
        for m in CURVE_METRICS:
            ms = _metric_summary([t for t in use if m in t.curves], m, grids[m], reps, seed)
            if ms is not None:
                metrics[m] = ms
                if ms.curve is not None and ms.curve.single_point:
                    missing.single_point.append((label, m))
        walls = [t.wall_time_s for t in use if np.isfinite(t.wall_time_s)]
        configs.append(
            ConfigSummary(
                key=key,
                label=label,
                trials=use,
                all_trials=trials,
                metrics=metrics,
                wall_time_s=float(np.mean(walls)) if walls else float("nan"),
            )
        )
    configs.sort(key=lambda c: _config_order(c, axes))
    return configs, missing


def _config_order(c: ConfigSummary, axes: list[str]):
    # Numeric axes (K, b) sort numerically so Fig. 2b reads K = 1, 2, ..., 10, not 1, 10, 2.
    t = c.all_trials[0]
    return tuple(natural_key(t.tags.get(a, "") if a != CONFIG_KEY_AXIS else c.key) for a in axes) + (c.key,)


def _metric_summary(trials: list[Trial], metric: str, grid: np.ndarray, reps: int, seed: int):
    if not trials:
        return None
    finals = np.array([t.curves[metric][1][-1] for t in trials])
    final_steps = np.array([t.curves[metric][0][-1] for t in trials])
    lo, hi = stats.bootstrap_ci(finals, reps=reps, seed=seed)
    to_thr = {}
    for thr in THRESHOLDS:
        s = np.array([stats.steps_to_threshold(*t.curves[metric], thr) for t in trials])
        to_thr[thr] = (float(stats.iqm(s)), int(np.isfinite(s).sum()))
    return MetricSummary(
        n_seeds=len(trials),
        final_iqm=float(stats.iqm(finals)),
        final_low=float(lo),
        final_high=float(hi),
        final_step=float(stats.iqm(final_steps)),
        to_threshold=to_thr,
        curve=_curve(trials, metric, grid, reps, seed),
    )


def _curve(trials: list[Trial], metric: str, grid: np.ndarray, reps: int, seed: int) -> CurveSummary:
    if max(len(t.curves[metric][0]) for t in trials) <= 1:
        # One evaluation per seed: the aggregate is a point, with the CI of that point.
        values = np.array([t.curves[metric][1][0] for t in trials])
        steps = np.array([t.curves[metric][0][0] for t in trials])
        lo, hi = stats.bootstrap_ci(values, reps=reps, seed=seed)
        return CurveSummary(
            grid=np.zeros(0),
            iqm=np.atleast_1d(stats.iqm(values)),
            low=np.atleast_1d(lo),
            high=np.atleast_1d(hi),
            coverage=np.array([len(trials)]),
            n_seeds=len(trials),
            single_point=True,
            point_step=float(np.median(steps)),
        )
    mat = np.stack([stats.interpolate(*t.curves[metric], grid) for t in trials])  # [n_seeds, G]
    low, high = stats.bootstrap_ci(mat, reps=reps, seed=seed)
    return CurveSummary(
        grid=grid,
        iqm=stats.iqm(mat),
        low=low,
        high=high,
        coverage=(~np.isnan(mat)).sum(axis=0),
        n_seeds=len(trials),
        single_point=False,
    )
