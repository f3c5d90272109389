"""Aggregate statistics over seeds: IQM, percentile-bootstrap confidence intervals, curve interpolation
onto a common env-step grid, env steps to reach a success threshold, the normalised area under a curve
and the probability of improvement of one configuration over another.

This follows rliable (Agarwal et al., 2021) without depending on it: rliable 1.2 is an sdist that pulls in
`arch`, `statsmodels`, `seaborn` and `absl-py` for what is, here, a few lines of numpy. A sweep has one
environment per experiment, so rliable's *stratified* bootstrap (resample runs within each task) reduces
to resampling seeds within one configuration, which is what `bootstrap_ci` does.

NaN marks "no data" (a seed that stopped before that step); statistics ignore it per column.
Infinity marks "never reached" in steps-to-threshold; the IQM trims it away when it is an outlier.

The bootstrap is exact where the seeds allow: with n seeds there are only C(2n - 1, n) different
resamples up to order (126 for 5 seeds), each standing for a known number of the n^n equally likely ordered
ones, so every resample is enumerated and the percentiles are those of the whole resampling distribution
(`np.percentile`'s linear rule over all n^n). Above `EXACT_LIMIT` different resamples (more than 8 seeds;
for P(X > Y), pairs of resamples) it draws `MC_REPS` (20,000) of them. `bootstrap_method` says which.

Honest intervals: a bootstrap over 2 or 3 seeds resamples almost nothing and gives intervals that look
precise and are not, and an IQM of fewer than 5 values trims nothing useful. So a CI, a band and the IQM
are used only from `MIN_SEEDS_FOR_CI` seeds on; with fewer, the mean and the seeds' range (`SeedSummary`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from itertools import combinations_with_replacement

import numpy as np

IQM_TRIM = 0.25  # trim 25 % from each end: the inter-quartile mean
MC_REPS = 20_000  # resamples drawn where enumerating them all is too costly (the rules' minimum)
DEFAULT_REPS = None  # None: exact where the seeds allow (EXACT_LIMIT), else MC_REPS
EXACT_LIMIT = 10_000  # different resamples of one configuration enumerated at most (8 seeds: 6,435)
EXACT_PAIR_LIMIT = 50_000_000  # pairs of resamples enumerated for P(X > Y) at most (8 seeds a side)
DEFAULT_CONFIDENCE = 0.95
MIN_SEEDS_FOR_CI = 5  # fewer seeds: no CI, no band, no IQM (the mean and the seeds' range instead)


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
    reps: int | None = DEFAULT_REPS,
    confidence: float = DEFAULT_CONFIDENCE,
    seed: int = 0,
    chunk: int = 250,
) -> tuple[np.ndarray, np.ndarray]:
    """Percentile-bootstrap CI of `statistic` over seeds (axis 0 of `x`, shape [n_seeds, ...]).

    `reps` None: exact (every resample, `resamples(n)`) up to `EXACT_LIMIT` different ones, else
    `MC_REPS` drawn. A number: exactly `np.random.default_rng(seed).integers(0, n, size=(reps, n))`, each
    row one bootstrap sample of seed indices, so a test can reproduce it. Bounds are the percentiles at
    (1 - confidence) / 2 and 1 - (1 - confidence) / 2, NaN left out per column. With one seed, or identical
    seeds, the interval collapses to the point estimate: there is nothing to resample.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    if n == 0:
        nan = np.full(x.shape[1:], np.nan)
        return nan, nan.copy()
    tail = 100.0 * (1.0 - confidence) / 2.0
    if reps is None and exact_bootstrap(n):
        idx, counts = resamples(n)
        boots = np.empty((len(idx),) + x.shape[1:])
        for lo in range(0, len(idx), chunk):
            boots[lo : lo + chunk] = statistic(x[idx[lo : lo + chunk]], axis=1)
        flat = boots.reshape(len(idx), -1)
        low = np.array([population_percentile(flat[:, j], counts, tail) for j in range(flat.shape[1])])
        high = np.array(
            [population_percentile(flat[:, j], counts, 100.0 - tail) for j in range(flat.shape[1])]
        )
        return low.reshape(x.shape[1:]), high.reshape(x.shape[1:])
    idx = np.random.default_rng(seed).integers(0, n, size=(reps or MC_REPS, n))
    boots = np.empty((len(idx),) + x.shape[1:])
    for lo in range(0, len(idx), chunk):  # chunks keep [chunk, n, grid] small for long curves
        sample = x[idx[lo : lo + chunk]]  # [chunk, n, ...]
        boots[lo : lo + chunk] = statistic(sample, axis=1)
    with np.errstate(invalid="ignore"), quiet_all_nan():
        low = np.nanpercentile(boots, tail, axis=0)
        high = np.nanpercentile(boots, 100.0 - tail, axis=0)
    return low, high


def exact_bootstrap(n: int) -> bool:
    """Whether every resample of `n` seeds is enumerated (C(2n - 1, n) <= EXACT_LIMIT: up to 8 seeds)."""
    return n > 0 and math.comb(2 * n - 1, n) <= EXACT_LIMIT


def bootstrap_method(n: int, reps: int | None = DEFAULT_REPS) -> str:
    """What a CI over `n` seeds was computed from, in words a table's note can carry."""
    if reps is None and exact_bootstrap(n):
        return f"exact: all {n}^{n} = {n**n:,} resamples of the {n} seeds"
    return f"{reps or MC_REPS:,} bootstrap resamples"


@cache
def resamples(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every bootstrap resample of `n` seeds up to order: the seed indices [M, n] of each (sorted) and how
    many of the n^n equally likely ordered resamples it stands for (the multinomial coefficient, int64)."""
    idx = np.array(list(combinations_with_replacement(range(n), n)), dtype=np.int64)
    counts = np.stack([np.bincount(row, minlength=n) for row in idx])
    ways = math.factorial(n) // np.array([math.prod(math.factorial(int(c)) for c in row) for row in counts])
    idx.setflags(write=False)
    return idx, ways.astype(np.int64)


def population_percentile(values: np.ndarray, counts: np.ndarray, q: float) -> float:
    """`np.percentile(population, q)` (its linear rule) of the population holding each of `values`
    `counts` times, without building it; NaN values are left out (as `np.nanpercentile` does)."""
    values = np.asarray(values, dtype=np.float64)
    keep = ~np.isnan(values)
    if not keep.any():
        return np.nan
    v, c = values[keep], np.asarray(counts)[keep]
    order = np.argsort(v, kind="stable")
    v, cum = v[order], np.cumsum(c[order])
    h = q / 100.0 * float(cum[-1] - 1)
    lo, hi = math.floor(h), math.ceil(h)
    # Element i of the sorted population is the first value whose cumulative count passes i.
    v_lo, v_hi = v[np.searchsorted(cum, lo, side="right")], v[np.searchsorted(cum, hi, side="right")]
    return float(v_lo + (h - lo) * (v_hi - v_lo))


class quiet_all_nan:
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


# ---------------------------------------------------------------------------------------------- over seeds


def has_ci(n_seeds: int) -> bool:
    """Whether `n_seeds` are enough for an IQM with a bootstrap CI (else: mean and range)."""
    return n_seeds >= MIN_SEEDS_FOR_CI


def center(x: np.ndarray, n_seeds: int | None = None) -> np.ndarray:
    """The point estimate over seeds (axis 0), ignoring NaN: the IQM from `MIN_SEEDS_FOR_CI` seeds on,
    else the mean. `n_seeds` decides for a whole matrix (a curve's columns have fewer seeds near its end)."""
    x = np.asarray(x, dtype=np.float64)
    # seeds (rows) with any value
    n = int((~np.isnan(x.reshape(len(x), -1))).any(axis=1).sum()) if n_seeds is None else n_seeds
    if has_ci(n):
        return iqm(x)
    valid = ~np.isnan(x)
    count = valid.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        total = np.where(valid, x, 0.0).sum(axis=0)  # inf stays inf ("never reached" drags the mean)
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)


@dataclass(frozen=True)
class SeedSummary:
    """One figure over a configuration's seeds: from `MIN_SEEDS_FOR_CI` seeds on the IQM and its
    percentile-bootstrap CI; with fewer, the mean and the seeds' [min, max] (`low`, `high`)."""

    n: int
    point: float
    low: float
    high: float
    confidence: float = DEFAULT_CONFIDENCE

    @property
    def has_ci(self) -> bool:
        return has_ci(self.n)

    @property
    def estimator(self) -> str:
        return "IQM" if self.has_ci else "mean"

    @property
    def interval(self) -> str:
        """What [low, high] is: a CI, the seeds' range, or nothing (one seed)."""
        if self.n == 0:
            return ""
        if self.has_ci:
            return f"{100 * self.confidence:g}% CI"
        return "range" if self.n > 1 else "n = 1"

    def text(self, fmt: str = ".3f") -> str:
        if self.n == 0 or not np.isfinite(self.point):
            return "-"
        p, lo, hi = (format(v, fmt) for v in (self.point, self.low, self.high))
        if self.has_ci:
            return f"IQM {p} [{self.interval} {lo}, {hi}]"
        if self.n == 1:
            return f"{p} (n = 1)"
        return f"mean {p}, range over {self.n} seeds: [{lo}, {hi}]"


def summarise_seeds(
    values: np.ndarray, reps: int = DEFAULT_REPS, seed: int = 0, confidence: float = DEFAULT_CONFIDENCE
) -> SeedSummary:
    """`SeedSummary` of one value per seed (NaN: that seed has none)."""
    x = np.asarray(values, dtype=np.float64)
    x = x[~np.isnan(x)]
    n = int(x.size)
    if n == 0:
        return SeedSummary(0, np.nan, np.nan, np.nan, confidence)
    if has_ci(n):
        low, high = bootstrap_ci(x, reps=reps, confidence=confidence, seed=seed)
        return SeedSummary(n, float(iqm(x)), float(low), float(high), confidence)
    return SeedSummary(n, float(np.mean(x)), float(np.min(x)), float(np.max(x)), confidence)


# ---------------------------------------------------------------------------------------------- area


def auc_window(step_arrays: list[np.ndarray]) -> tuple[float, float]:
    """The env-step window every curve covers: from the latest first evaluation to the earliest last
    one. Curves with fewer than two evaluations have no area and are left out. (nan, nan) when the
    window is empty.

    Why this window: starting at 0 would invent a success of 0 (or anything) before the first
    evaluation, and ending past a seed's last evaluation would extrapolate it; one window for every
    configuration keeps their areas comparable. For a finished sweep it ends within one evaluation of
    the env-step budget.
    """
    arrays = [np.asarray(s, dtype=np.float64) for s in step_arrays if len(s) >= 2]
    if not arrays:
        return np.nan, np.nan
    start = max(float(s.min()) for s in arrays)
    end = min(float(s.max()) for s in arrays)
    return (start, end) if end > start else (np.nan, np.nan)


def normalised_auc(steps: np.ndarray, values: np.ndarray, start: float, end: float) -> float:
    """Area under the linearly interpolated curve over [start, end] divided by end - start (so a
    success curve gives a number in [0, 1]); NaN when the curve does not cover the window."""
    if not (np.isfinite(start) and np.isfinite(end) and end > start):
        return np.nan
    steps = np.asarray(steps, dtype=np.float64)
    inner = steps[(steps > start) & (steps < end)]
    grid = np.union1d([start, end], inner)  # every kink of the piecewise-linear curve: the trapezoid is exact
    y = interpolate(steps, values, grid)
    if np.isnan(y).any():
        return np.nan
    return float(np.sum((y[1:] + y[:-1]) * np.diff(grid)) / 2.0 / (end - start))


# ---------------------------------------------------------------------------------------------- P(X > Y)


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) (Agarwal et al. 2021): the share of (seed of X, seed of Y) pairs where X's score is
    higher, ties counting 1/2 (the Mann-Whitney U statistic over nx * ny). NaN scores are left out."""
    x, y = _valid(x)[:, None], _valid(y)[None, :]
    if not (x.size and y.size):
        return np.nan
    return float(np.mean((x > y) + 0.5 * (x == y)))


@dataclass(frozen=True)
class Improvement:
    """P(X > Y) with its percentile-bootstrap CI, or why there is none (fewer than 5 seeds on a side)."""

    p: float
    low: float
    high: float
    nx: int
    ny: int
    confidence: float = DEFAULT_CONFIDENCE

    @property
    def available(self) -> bool:
        return has_ci(self.nx) and has_ci(self.ny)

    def text(self, fmt: str = ".2f") -> str:
        if not (self.nx and self.ny):
            return f"n/a (no seeds on a side; here {self.nx} and {self.ny})"
        if not self.available:  # the point estimate still says something; its interval needs the seeds
            return f"{format(self.p, fmt)} (no CI: n = {self.nx} and {self.ny}; a CI needs {MIN_SEEDS_FOR_CI} each)"
        p, lo, hi = (format(v, fmt) for v in (self.p, self.low, self.high))
        return f"{p} [{100 * self.confidence:g}% CI {lo}, {hi}]"

    def reading(self) -> str:
        """The CI against 0.5, the comparison's fixed rule: "ahead" (wholly above), "behind" (wholly below),
        "not separated" (it holds 0.5); without a CI (under 5 seeds a side) there is no reading, said so."""
        if not self.available:
            return f"no reading (n = {self.nx} and {self.ny}; a CI needs {MIN_SEEDS_FOR_CI} each)"
        if self.low > 0.5:
            return "ahead"
        if self.high < 0.5:
            return "behind"
        return "not separated"


def improvement(
    x: np.ndarray,
    y: np.ndarray,
    reps: int | None = DEFAULT_REPS,
    seed: int = 0,
    confidence: float = DEFAULT_CONFIDENCE,
) -> Improvement:
    """`probability_of_improvement` of X over Y and, when both have `MIN_SEEDS_FOR_CI` seeds, its
    percentile-bootstrap CI: the seeds of X and of Y resampled independently (rliable's scheme with one
    task), each replicate's P(X > Y) computed, the percentiles taken. `reps` None: exact, every pair of
    resamples (up to `EXACT_PAIR_LIMIT` pairs: 8 seeds a side), else `MC_REPS` drawn."""
    x, y = _valid(x), _valid(y)
    point = probability_of_improvement(x, y)
    if not (has_ci(x.size) and has_ci(y.size)):
        return Improvement(point, np.nan, np.nan, int(x.size), int(y.size), confidence)
    tail = 100.0 * (1.0 - confidence) / 2.0
    if reps is None and exact_improvement(x.size, y.size):
        values, counts = _improvement_distribution(x, y)
        low, high = (population_percentile(values, counts, q) for q in (tail, 100.0 - tail))
        return Improvement(point, low, high, int(x.size), int(y.size), confidence)
    rng = np.random.default_rng(seed)
    reps = reps or MC_REPS
    xb = x[rng.integers(0, x.size, size=(reps, x.size))][:, :, None]
    yb = y[rng.integers(0, y.size, size=(reps, y.size))][:, None, :]
    boots = ((xb > yb) + 0.5 * (xb == yb)).mean(axis=(1, 2))
    low, high = np.percentile(boots, [tail, 100.0 - tail])
    return Improvement(point, float(low), float(high), int(x.size), int(y.size), confidence)


def exact_improvement(nx: int, ny: int) -> bool:
    """Whether every pair of resamples of `nx` and `ny` seeds is enumerated for P(X > Y)'s CI."""
    return (
        exact_bootstrap(nx)
        and exact_bootstrap(ny)
        and (math.comb(2 * nx - 1, nx) * math.comb(2 * ny - 1, ny) <= EXACT_PAIR_LIMIT)
    )


def _improvement_distribution(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P(X* > Y*) over every pair of resamples, as its distinct values and how many of the nx^nx * ny^ny
    ordered pairs give each. A resample is a count per seed, so P* = cx . W . cy / (nx ny) with W the
    pairwise win matrix (1, 1/2 on ties), and 2 nx ny P* is an integer: a histogram holds it exactly."""
    (ix, wx), (iy, wy) = resamples(x.size), resamples(y.size)
    cx = np.stack([np.bincount(r, minlength=x.size) for r in ix])  # [Mx, nx]
    cy = np.stack([np.bincount(r, minlength=y.size) for r in iy])  # [My, ny]
    win2 = 2 * (x[:, None] > y[None, :]) + (x[:, None] == y[None, :])  # 2 W, integers
    right = win2 @ cy.T  # [nx, My]
    top = 2 * x.size * y.size
    hist = np.zeros(top + 1, dtype=np.int64)
    for lo in range(0, len(cx), 512):
        k = cx[lo : lo + 512] @ right  # [chunk, My] integers 0..top
        ways = wx[lo : lo + 512, None] * wy[None, :]
        hist += _weighted_counts(k, ways, top)
    seen = np.flatnonzero(hist)
    return seen / top, hist[seen]


def _weighted_counts(k: np.ndarray, ways: np.ndarray, top: int) -> np.ndarray:
    """Integer-weighted histogram of `k` (bincount's weights are floats: summed here in int64 instead)."""
    order = np.argsort(k.ravel(), kind="stable")
    ks, ws = k.ravel()[order], ways.ravel()[order]
    out = np.zeros(top + 1, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    out[ks[starts]] = np.add.reduceat(ws, starts)
    return out


def _valid(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64).ravel()
    return x[~np.isnan(x)]


# ---------------------------------------------------------------------------------------------- paired

PAIRED_ALPHA = 0.05  # the paired test's level, after Holm's correction


@dataclass(frozen=True)
class SignedRank:
    """The exact two-sided Wilcoxon signed-rank test over paired differences (`signed_rank_test`)."""

    n: int  # the nonzero differences the test stands on
    zeros: int  # differences of exactly 0, dropped before ranking (Wilcoxon's own treatment)
    w_plus: float  # the sum of the ranks of the positive differences (average ranks where |d| ties)
    w_minus: float  # of the negative ones
    p: float  # two-sided; 1 when every difference is 0; NaN without any pair
    method: str  # how p was computed, in words

    @property
    def statistic(self) -> float:
        """scipy's two-sided W: the smaller of the two rank sums."""
        return min(self.w_plus, self.w_minus)


def signed_rank_test(differences: np.ndarray) -> SignedRank:
    """The exact two-sided Wilcoxon signed-rank test of paired differences (one per seed).

    Zero differences are dropped before ranking (Wilcoxon's treatment, scipy's zero_method="wilcox"); the
    rest are ranked by |d| with average ranks for ties (after rounding to 12 decimals, so that float noise
    splits no tie). Without ties p is `scipy.stats.wilcoxon(d,
    method="exact")`'s: the null distribution of W+ over the 2^n equally likely sign patterns. With ties
    scipy's table is not exact for average ranks (it rounds W conservatively), so every one of the 2^n
    sign patterns of the tied ranks is enumerated instead (up to 20 pairs): p = 2 min(P(W+ <= w),
    P(W+ >= w)), capped at 1, the same two-sided rule. NaN differences (a seed without the figure on a
    side) are left out. Eight positive differences give the smallest p, 2 / 2^8 = 0.0078; five give 2 / 32
    = 0.0625, which no difference of five pairs can go below."""
    from scipy.stats import rankdata, wilcoxon

    d = np.asarray(differences, dtype=np.float64).ravel()
    # Zeros and ties that floating-point arithmetic split (0.525 - 0.45 against 0.375 - 0.45; rates of
    # 100 tasks and their means are exact decimals) are zeros and ties: rounded to 12 decimals first.
    d = np.round(d[~np.isnan(d)], 12)
    nonzero = d[d != 0]
    zeros, n = int(d.size - nonzero.size), int(nonzero.size)
    if d.size == 0:
        return SignedRank(0, 0, np.nan, np.nan, np.nan, "no pairs")
    if n == 0:
        return SignedRank(0, zeros, 0.0, 0.0, 1.0, "every difference is 0: p = 1")
    ranks = rankdata(np.abs(nonzero))  # average ranks for ties
    w_plus, w_minus = float(ranks[nonzero > 0].sum()), float(ranks[nonzero < 0].sum())
    if len(np.unique(np.abs(nonzero))) == n:
        p = float(wilcoxon(nonzero, method="exact").pvalue)
        how = f"exact (scipy.stats.wilcoxon, method='exact', all 2^{n} sign patterns)"
    elif n <= 20:
        signs = ((np.arange(2**n)[:, None] >> np.arange(n)) & 1).astype(np.float64)  # [2^n, n]
        null = signs @ ranks  # W+ of every sign pattern
        tol = 1e-9
        p = float(min(1.0, 2 * min(np.mean(null <= w_plus + tol), np.mean(null >= w_plus - tol))))
        how = f"exact with tied |differences| (average ranks; all 2^{n} sign patterns enumerated)"
    else:
        p = float(wilcoxon(nonzero, method="asymptotic").pvalue)
        how = "normal approximation (more than 20 tied pairs)"
    return SignedRank(n, zeros, w_plus, w_minus, p, how)


def holm(pvalues) -> np.ndarray:
    """Holm's step-down adjusted p-values of one family of tests (NaN: no test, left out of the family):
    the i-th smallest of m becomes max over j <= i of min(1, (m - j + 1) p_(j)). Rejecting where the
    adjusted p is below alpha controls the family-wise error at alpha."""
    p = np.asarray(pvalues, dtype=np.float64)
    out = np.full(p.shape, np.nan)
    tested = np.flatnonzero(~np.isnan(p))
    m = tested.size
    order = tested[np.argsort(p[tested], kind="stable")]
    running = 0.0
    for i, j in enumerate(order):
        running = max(running, min(1.0, (m - i) * p[j]))
        out[j] = running
    return out
