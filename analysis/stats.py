"""Aggregate statistics over seeds: IQM, percentile-bootstrap confidence intervals, curve interpolation
onto a common env-step grid, and env steps to reach a success threshold.

This follows rliable (Agarwal et al., 2021) without depending on it: rliable 1.2 is an sdist that pulls in
`arch`, `statsmodels`, `seaborn` and `absl-py` for what is, here, a few lines of numpy. A sweep has one
environment per experiment, so rliable's *stratified* bootstrap (resample runs within each task) reduces
to resampling seeds within one configuration, which is what `bootstrap_ci` does.

NaN marks "no data" (a seed that stopped before that step); statistics ignore it per column.
Infinity marks "never reached" in steps-to-threshold; the IQM trims it away when it is an outlier.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

IQM_TRIM = 0.25  # trim 25 % from each end: the inter-quartile mean
DEFAULT_REPS = 2000
DEFAULT_CONFIDENCE = 0.95


def iqm(x: np.ndarray, axis: int = 0) -> np.ndarray:
    """Inter-quartile mean along `axis`, ignoring NaN.

    Same definition as `scipy.stats.trim_mean(x, 0.25)` (which rliable uses): with n valid values,
    g = floor(0.25 * n) values are cut from each end and the rest averaged. So n = 4 averages the middle
    two, n <= 3 is the plain mean. A column with no valid value gives NaN. +inf is a valid value (it is
    "never reached"): it survives only when it is not trimmed, and then the IQM is inf.
    """
    x = np.moveaxis(np.asarray(x, dtype=np.float64), axis, 0)
    valid = ~np.isnan(x)
    n = valid.sum(axis=0)
    xs = np.sort(x, axis=0)  # NaN sorts last, +inf just before it
    g = np.floor(IQM_TRIM * n).astype(np.int64)
    rank = np.arange(x.shape[0]).reshape((-1,) + (1,) * (x.ndim - 1))
    keep = (rank >= g) & (rank < n - g)
    with np.errstate(invalid="ignore", divide="ignore"):
        # Summing with a mask (not cumsum) so that inf - inf never appears.
        total = np.where(keep, xs, 0.0).sum(axis=0)
        out = total / (n - 2 * g)
    return np.where(n > 0, out, np.nan)


def bootstrap_ci(
    x: np.ndarray,
    statistic: Callable[[np.ndarray], np.ndarray] = iqm,
    reps: int = DEFAULT_REPS,
    confidence: float = DEFAULT_CONFIDENCE,
    seed: int = 0,
    chunk: int = 250,
) -> tuple[np.ndarray, np.ndarray]:
    """Percentile-bootstrap CI of `statistic` over seeds (axis 0 of `x`, shape [n_seeds, ...]).

    The resampling is exactly `np.random.default_rng(seed).integers(0, n, size=(reps, n))`, each row one
    bootstrap sample of seed indices, so a test can reproduce it. Bounds are `np.nanpercentile` at
    (1 - confidence) / 2 and 1 - (1 - confidence) / 2. With one seed, or identical seeds, the interval
    collapses to the point estimate: there is nothing to resample.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    if n == 0:
        nan = np.full(x.shape[1:], np.nan)
        return nan, nan.copy()
    idx = np.random.default_rng(seed).integers(0, n, size=(reps, n))
    boots = np.empty((reps,) + x.shape[1:])
    for lo in range(0, reps, chunk):  # chunks keep [chunk, n, grid] small for long curves
        sample = x[idx[lo : lo + chunk]]  # [chunk, n, ...]
        boots[lo : lo + chunk] = statistic(sample, axis=1)
    tail = 100.0 * (1.0 - confidence) / 2.0
    with np.errstate(invalid="ignore"), _quiet_all_nan():
        low = np.nanpercentile(boots, tail, axis=0)
        high = np.nanpercentile(boots, 100.0 - tail, axis=0)
    return low, high


class _quiet_all_nan:
    """nanpercentile warns on all-NaN columns (steps no seed reached); NaN is the right answer there."""

    def __enter__(self):
        import warnings

        self._ctx = warnings.catch_warnings()
        self._ctx.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


def interpolate(steps: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear interpolation of one seed's curve onto `grid`; NaN outside [first step, last step].

    No extrapolation: a seed that stopped early must not pretend to know its later success.
    """
    steps = np.asarray(steps, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    grid = np.asarray(grid, dtype=np.float64)
    out = np.full(grid.shape, np.nan)
    if steps.size == 0:
        return out
    order = np.argsort(steps, kind="stable")
    steps, values = steps[order], values[order]
    inside = (grid >= steps[0]) & (grid <= steps[-1])
    out[inside] = np.interp(grid[inside], steps, values)
    return out


def steps_to_threshold(steps: np.ndarray, values: np.ndarray, threshold: float) -> float:
    """The first evaluated env step at which success >= threshold; +inf if never.

    No interpolation between evaluations: the report states what was measured.
    """
    steps = np.asarray(steps, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    order = np.argsort(steps, kind="stable")
    hit = np.nonzero(values[order] >= threshold)[0]
    return float(steps[order][hit[0]]) if hit.size else float("inf")


def common_grid(step_arrays: list[np.ndarray], points: int = 200, max_points: int = 400) -> np.ndarray:
    """An env-step grid over all curves: evenly spaced points plus every evaluated step (so a seed with a
    single evaluation still lands on the grid), thinned to `max_points` when there are too many."""
    arrays = [np.asarray(s, dtype=np.float64) for s in step_arrays if len(s)]
    if not arrays:
        return np.zeros(0)
    every = np.unique(np.concatenate(arrays))
    lin = np.linspace(every[0], every[-1], points)
    grid = np.union1d(lin, every)
    if grid.size > max_points:
        grid = np.union1d(np.linspace(every[0], every[-1], max_points), every[[0, -1]])
    return grid
