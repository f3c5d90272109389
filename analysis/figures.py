"""PNG figures: success against environment steps, final success per configuration (paper Fig. 2b when
the axis is K), and the evolution of one task's sub-goal tree over training (paper Fig. 4d).

Intervals follow `stats.MIN_SEEDS_FOR_CI`: from 5 seeds on, the IQM with a shaded 95 % bootstrap band
(curves) or error bars (bars); with fewer, the mean with each seed drawn (thin lines, dots: their range)
and no band, so that two seeds never look like a confident estimate.

What has no data is not drawn: a panel no configuration has data for, a configuration without the metric
(never a bar of 0), a figure with nothing in it (the function returns None); each says why in `notes`, which
the report prints. Titles are wrapped to the figure's width (`_suptitle`), env-step axes read 20k / 1.5M
(`steps_axis`), and the caller names the paper's figure only where the env is the paper's (`report`).
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never a display (the report runs on headless machines)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from copilot_ray.keys import (  # noqa: E402
    EVAL_MASTERED,
    EVAL_RETURN,
    EVAL_SUCCESS,
    PRIVILEGE_COLLISION_CHECKS,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    SWEEP_TAG,
)

from . import stats  # noqa: E402
from .aggregate import ConfigSummary, CurveSummary, final_words  # noqa: E402

TITLES = {
    EVAL_SUCCESS: "each method's headline (CO-PILOT, SoRB, RRT* curriculum: along their plans; SAC, HER, PPO: "
    "agent alone)",
    SUCCESS_PLANNED: "agent following its plan's finest path (SoRB: its graph's waypoints; HER: = agent alone)",
    SUCCESS_DIRECT: "agent alone (no planner)",
    EVAL_RETURN: "task reward R for reaching the goal, same rollouts as success",
    EVAL_MASTERED: "track distributions whose mean walker return exceeds 230",
}
# The y axis of a metric other than a success rate: (label, limits or None for automatic).
Y_AXES = {
    EVAL_RETURN: ("average return on held-out tasks", None),
    EVAL_MASTERED: ("share of evaluation distributions mastered", (-0.02, 1.02)),
}
SUCCESS_AXIS = ("success rate on held-out tasks", (-0.02, 1.02))
MAX_CURVES = 12  # more lines than this are unreadable; the best ones by final success are kept
PLANNED_AND_DIRECT = (SUCCESS_PLANNED, SUCCESS_DIRECT)
BY_METHOD = (EVAL_SUCCESS,)  # the paper's Fig. 2a / 4a: one figure every algorithm reports
RETURN = (EVAL_RETURN,)  # the paper's Fig. 2d (Ant maze)
MASTERED = (EVAL_MASTERED,)  # the paper's Fig. 3 (stump-track walker)
DPI = 120


def _colors(n: int):
    cmap = plt.get_cmap("tab10" if n <= 10 else "tab20")
    return [cmap(i % cmap.N) for i in range(n)]


def _select(configs: list[ConfigSummary]) -> tuple[list[ConfigSummary], int]:
    """At most MAX_CURVES configurations: each method's best by final success first (a method is an
    algorithm in one sweep: a comparison's parts), so that none vanishes from a crowded figure, then
    the best of the rest. (the ones kept, in their order; how many were left out)"""
    if len(configs) <= MAX_CURVES:
        return configs, 0

    def score(c):
        m = c.metrics.get(EVAL_SUCCESS) or c.metrics.get(SUCCESS_PLANNED)
        return m.final.point if m and np.isfinite(m.final.point) else -1.0

    def method(c):
        return c.algorithm, c.all_trials[0].tags.get(SWEEP_TAG, "")

    ranked = sorted(configs, key=score, reverse=True)
    keep, methods = [], set()
    for c in ranked:
        if method(c) not in methods:
            methods.add(method(c))
            keep.append(c)
    keep = keep[:MAX_CURVES]
    kept = {id(c) for c in keep}
    keep += [c for c in ranked if id(c) not in kept][: MAX_CURVES - len(keep)]
    kept = {id(c) for c in keep}
    return [c for c in configs if id(c) in kept], len(configs) - MAX_CURVES


def wrap(text: str, width_in: float, fontsize: float) -> str:
    """`text` broken into lines that fit `width_in` inches at `fontsize` points (each line of it apart)."""
    chars = max(16, int(width_in * 72 / (0.6 * fontsize)))
    return "\n".join(textwrap.fill(line, chars) for line in text.split("\n"))


def _suptitle(fig, text: str, fontsize: float = 10) -> None:
    """The figure's title, wrapped to its width (with a constrained or tight layout it never clips)."""
    fig.suptitle(wrap(text, fig.get_figwidth() * 0.95, fontsize), fontsize=fontsize)


def _steps_label(x: float, _pos=None) -> str:
    for scale, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if abs(x) >= scale:
            return f"{x / scale:.3g}{unit}"
    return f"{x:.3g}"


def steps_axis(ax, log: bool = False) -> None:
    """An env-step x axis: ticks read 20k, 1.5M (no "1e4" offset), at most 6 of them, never crowded."""
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter

    if log:
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(numticks=6))
        ax.xaxis.set_minor_formatter(NullFormatter())  # "2x10^4 3x10^4 ..." between decades overlap
    else:
        ax.xaxis.set_major_locator(MaxNLocator(nbins=6, min_n_ticks=3))
    ax.xaxis.set_major_formatter(FuncFormatter(_steps_label))


def constant_value(curves) -> float | None:
    """The one value every point of `curves` ((steps, values) pairs) has, or None when they vary (or hold
    no number): a panel of such curves is a flat line that says nothing a table does not say better."""
    values = np.concatenate([np.asarray(v, dtype=float) for _, v in curves]) if curves else np.array([])
    values = values[np.isfinite(values)]
    if not values.size or np.ptp(values) > 1e-9 * max(1.0, float(np.abs(values).max())):
        return None
    return float(values[0])


def _has_curve(c: ConfigSummary, metric: str) -> bool:
    return metric in c.metrics and c.metrics[metric].curve is not None


def success_curves(
    configs: list[ConfigSummary],
    axis_name: str,
    path: Path,
    metrics: tuple[str, ...] = PLANNED_AND_DIRECT,
    title: str = "Success against environment steps",
    notes: list[str] | None = None,
) -> Path | None:
    """One panel per metric that some configuration has (planned and direct; `BY_METHOD`: the common
    success), one colour per configuration: IQM over seeds and its 95 % bootstrap band from 5 seeds on,
    else the mean and each seed as a thin line (no band). Solid where every seed of the configuration has
    data, dashed where only some do (seeds are never extrapolated past their last evaluation). None (and
    a note) when no configuration has any of `metrics`."""
    notes = [] if notes is None else notes
    shown, dropped = _select(configs)
    drawn = [m for m in metrics if any(_has_curve(c, m) for c in shown)]
    if not drawn:
        notes.append(f"{path.name}: not drawn: no configuration logged {_leaves(metrics)}.")
        return None
    for m in metrics:
        if m not in drawn:
            notes.append(f"{path.name}: no {_leaf(m)} panel: no configuration logged {m}.")
    blank = [c.label for c in shown if not any(_has_curve(c, m) for m in drawn)]
    if blank:
        notes.append(f"{path.name}: not drawn (no evaluation of {_leaves(drawn)}): {'; '.join(blank)}.")
    shown = [c for c in shown if c.label not in blank]
    colors = _colors(len(shown))
    fig, axes = plt.subplots(
        1, len(drawn), figsize=(5.2 * len(drawn) + 3.2, 4.6), sharey=True, squeeze=False, layout="constrained"
    )
    axes = axes[0]
    for ax, metric in zip(axes, drawn, strict=True):
        for c, color in zip(shown, colors, strict=True):
            m = c.metrics.get(metric)
            if m is None or m.curve is None:
                continue
            cv = m.curve
            label = f"{c.label} ({seeds_label(cv.n_seeds)})"
            if cv.single_point:
                _point(ax, cv, color, label + ", 1 eval")
                continue
            some = cv.coverage > 0
            full = cv.coverage == cv.n_seeds
            if cv.has_ci:
                ax.fill_between(cv.grid, cv.low, cv.high, where=some, color=color, alpha=0.18, linewidth=0)
            else:  # too few seeds for a band: each seed, thin (together: the range)
                for steps, values in cv.seed_curves:
                    ax.plot(steps, values, color=color, linewidth=0.7, alpha=0.55)
            ax.plot(
                cv.grid,
                np.where(some, cv.center, np.nan),
                color=color,
                linestyle="--",
                linewidth=1,
                alpha=0.7,
            )
            ax.plot(cv.grid, np.where(full, cv.center, np.nan), color=color, linewidth=2, label=label)
        ax.set_title(wrap(f"{_leaf(metric)}: {TITLES[metric]}", 5.0, 9), fontsize=9)
        ax.set_xlabel("environment steps")
        ylabel, ylim = Y_AXES.get(metric, SUCCESS_AXIS)
        if ylim is not None:
            ax.set_ylim(*ylim)
        ax.grid(alpha=0.3)
        steps_axis(ax)
    axes[0].set_ylabel(Y_AXES.get(drawn[0], SUCCESS_AXIS)[0])
    handles, labels = {}, []
    for ax in axes:  # every configuration once, whichever panel it appears in
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in handles:
                handles[lab] = h
                labels.append(lab)
    if labels:
        wrapped = [wrap(lab, 3.0, 8) for lab in labels]
        fig.legend(
            [handles[lab] for lab in labels], wrapped, loc="outside right center", fontsize=8, title=axis_name
        )
        # Long labels (a search's configurations) stack taller than the panels: the figure grows with
        # them, so that the legend does not run over the title.
        lines = sum(w.count("\n") + 1 for w in wrapped) + 2
        fig.set_figheight(max(fig.get_figheight(), 0.16 * lines + 1.6))
    note = INTERVAL_NOTE + "; dashed: not all seeds have reached this step"
    if dropped:
        note += f"; {dropped} more configurations not drawn"
    _suptitle(fig, f"{title}, by {axis_name}\n{note}")
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def _leaf(metric: str) -> str:
    return metric.split("/")[-1]


def _leaves(metrics) -> str:
    return " / ".join(_leaf(m) for m in metrics)


def seeds_label(n: int) -> str:
    """The legend's account of a configuration's seeds: what its line and interval are."""
    if stats.has_ci(n):
        return f"n = {n} seeds, IQM, 95% CI"
    return f"n = {n} seeds, range" if n > 1 else "n = 1 seed"


INTERVAL_NOTE = (
    f"n >= {stats.MIN_SEEDS_FOR_CI} seeds: IQM, shaded 95% stratified bootstrap CI; "
    f"fewer: mean (thick) and each seed (thin), no CI"
)


def _point(ax, cv: CurveSummary, color, label: str) -> None:
    """A configuration whose seeds evaluated once: a marker, with error bars only when they are a CI."""
    if cv.has_ci:
        err = np.clip(np.array([[cv.center[0] - cv.low[0]], [cv.high[0] - cv.center[0]]]), 0, None)
        ax.errorbar([cv.point_step], cv.center, yerr=err, fmt="o", color=color, capsize=4, label=label)
        return
    ax.plot([cv.point_step], cv.center, "o", color=color, label=label)
    for steps, values in cv.seed_curves:
        ax.plot(steps[:1], values[:1], ".", color=color, alpha=0.6)


BAR_FONT = 8  # the bars' tick labels
CHECKS_LINEAR_BELOW = 1e3  # the checks axis is logarithmic above this and linear below (0: no map)


def checks_at(c: ConfigSummary, steps: np.ndarray, metric: str = EVAL_SUCCESS) -> np.ndarray | None:
    """The collision checks a configuration had spent by each of `steps` (env steps), averaged over
    seeds: each seed's count (`copilot/privileges/collision_checks`, cumulative) read at its evaluations
    of `metric` and interpolated between them as its success curve is, so that a point of success
    against checks pairs a success with the checks spent by the same evaluations (a method that checks
    only inside evaluations, SoRB with the map, jumps at each); outside its evaluations, the count
    itself. None when none of its runs logged the count."""
    per_seed = []
    for t in c.trials:
        if PRIVILEGE_COLLISION_CHECKS not in t.curves:
            continue
        counts = np.interp(steps, *t.curves[PRIVILEGE_COLLISION_CHECKS])
        evaluated = t.curves.get(metric, (np.zeros(0), np.zeros(0)))[0]
        if len(evaluated) > 1:
            inside = (steps >= evaluated[0]) & (steps <= evaluated[-1])
            at_evaluations = np.interp(evaluated, *t.curves[PRIVILEGE_COLLISION_CHECKS])
            counts[inside] = np.interp(steps[inside], evaluated, at_evaluations)
        per_seed.append(counts)
    if not per_seed:
        return None
    return np.mean(per_seed, axis=0)


def success_vs_checks(
    configs: list[ConfigSummary],
    axis_name: str,
    path: Path,
    metric: str = EVAL_SUCCESS,
    title: str = "Test success against collision checks",
    notes: list[str] | None = None,
) -> Path | None:
    """Success (`metric`, each method's headline) against the ground-truth collision checks spent so far
    (the map's answers; paper Fig. 4c's axis): one line per configuration that used any, at the IQM over
    seeds (band: its 95 % CI from 5 seeds on) and the seeds' mean checks at each env step; one that used
    none is one point at 0 checks, its final success with its interval. None (and a note) when no
    configuration logged both the metric and its checks, or none used a check."""
    notes = [] if notes is None else notes
    shown, dropped = _select(configs)
    drawn = []
    for c in shown:
        m = c.metrics.get(metric)
        if m is None or m.curve is None:
            continue
        checks = checks_at(c, m.curve.grid, metric)
        if checks is None:
            notes.append(
                f"{path.name}: {c.label} not drawn: its runs did not log {PRIVILEGE_COLLISION_CHECKS}."
            )
            continue
        drawn.append((c, m, checks))
    if not any(checks.max() > 0 for _, _, checks in drawn):
        notes.append(f"{path.name}: not drawn: no configuration used a collision check.")
        return None
    fig, ax = plt.subplots(figsize=(8.8, 4.8), layout="constrained")
    for (c, m, checks), color in zip(drawn, _colors(len(drawn)), strict=True):
        label = f"{c.label} ({seeds_label(m.n_seeds)})"
        if checks.max() == 0:
            f = m.final
            err = np.clip(np.array([[f.point - f.low], [f.high - f.point]]), 0, None)
            ax.errorbar([0.0], [f.point], yerr=err, fmt="s", color=color, capsize=4, label=label + ", no map")
            continue
        cv = m.curve
        some = cv.coverage > 0
        if cv.has_ci:
            ax.fill_between(checks, cv.low, cv.high, where=some, color=color, alpha=0.18, linewidth=0)
        ax.plot(checks, np.where(some, cv.center, np.nan), color=color, linewidth=2, label=label)
        ax.plot(checks[some][-1:], cv.center[some][-1:], "o", color=color)  # where the budget ends
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    ax.set_xscale("symlog", linthresh=CHECKS_LINEAR_BELOW)
    ax.set_xlim(left=-CHECKS_LINEAR_BELOW * 0.3)
    # 0 (no map), then the powers of ten from the linear threshold on: symlog's own ticks put a "100" on
    # top of the "0" in the narrow linear stretch
    decades = int(np.ceil(np.log10(max(CHECKS_LINEAR_BELOW, *(c.max() for _, _, c in drawn)))))
    ax.xaxis.set_major_locator(
        FixedLocator([0.0] + [10.0**k for k in range(int(np.log10(CHECKS_LINEAR_BELOW)), decades + 1)])
    )
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _pos=None: _steps_label(x) if x >= 0 else ""))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("ground-truth collision checks spent so far (log scale above 1,000; 0: no map)")
    ax.set_ylabel(SUCCESS_AXIS[0])
    ax.set_ylim(*SUCCESS_AXIS[1])
    ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(
        handles,
        [wrap(lab, 3.0, 8) for lab in labels],
        loc="outside right center",
        fontsize=8,
        title=axis_name,
    )
    note = (
        f"n >= {stats.MIN_SEEDS_FOR_CI} seeds: IQM, shaded 95% stratified bootstrap CI; fewer: the mean, no "
        "CI; x: the seeds' mean checks at each env step; a dot: the last evaluation"
    )
    if dropped:
        note += f"; {dropped} more configurations not drawn"
    _suptitle(fig, f"{title}, by {axis_name}\n{note}")
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def final_success(
    configs: list[ConfigSummary],
    axis_name: str,
    path: Path,
    metrics: tuple[str, ...] = PLANNED_AND_DIRECT,
    paper: str = "",
    notes: list[str] | None = None,
    tasks: str = "test",
) -> Path | None:
    """Grouped bars (one per metric some configuration has: planned and direct, or `BY_METHOD`'s common
    success) of final success, each seed as a dot: the IQM with its 95 % CI from 5 seeds on, else the
    mean without error bars (the dots are the range). A configuration without the metric has no bar
    (never a bar of 0). `paper`: the paper's figure this is (the caller knows the env), or ""."""
    notes = [] if notes is None else notes
    shown, dropped = _select(configs)
    drawn = [m for m in metrics if any(m in c.metrics for c in shown)]
    if not drawn:
        notes.append(f"{path.name}: not drawn: no configuration logged {_leaves(metrics)}.")
        return None
    for m in metrics:
        if m not in drawn:
            notes.append(f"{path.name}: no {_leaf(m)} bars: no configuration logged {m}.")
    blank = [c.label for c in shown if not any(m in c.metrics for m in drawn)]
    if blank:
        notes.append(f"{path.name}: no bars (no evaluation of {_leaves(drawn)}): {'; '.join(blank)}.")
    shown = [c for c in shown if c.label not in blank]
    # Tick labels: one line per axis value, so that they stack instead of running into each other.
    # One line per axis value (a search's config key: per searched value), so that they stack.
    ticks = [c.label.replace(", ", "\n").replace(",", "\n") + f"\n(n = {c.n_seeds})" for c in shown]
    longest = max(len(line) for t in ticks for line in t.split("\n"))
    per_bar = max(0.9, 0.62 * BAR_FONT / 72 * longest + 0.25)  # inches a label needs
    width = per_bar * len(shown) + 2.2
    crowded = width > 20  # too many to stand side by side: slanted
    lines = max(t.count("\n") + 1 for t in ticks)
    # the labels' height below the axis (slanted: half their length more), so the bars keep theirs
    height = 4.8 + 0.14 * lines + (0.5 * 0.62 * BAR_FONT / 72 * longest if crowded else 0.0)
    x = np.arange(len(shown))
    bar = 0.76 / len(drawn)
    fig, ax = plt.subplots(figsize=(min(max(6.0, width), 20), height), layout="constrained")
    palette = ("tab:blue", "tab:orange", "tab:green")
    for i, metric in enumerate(drawn):
        offset, color = (i - (len(drawn) - 1) / 2) * bar, palette[i % len(palette)]
        have = [j for j, c in enumerate(shown) if metric in c.metrics]
        vals = [shown[j].metrics[metric].final.point for j in have]
        ax.bar(x[have] + offset, vals, bar, color=color, alpha=0.8, label=_leaf(metric))
        with_ci = [j for j in have if shown[j].metrics[metric].final.has_ci]
        if with_ci:  # error bars only where they are a CI
            finals = [shown[j].metrics[metric].final for j in with_ci]
            err = np.clip([[f.point - f.low for f in finals], [f.high - f.point for f in finals]], 0, None)
            points = [f.point for f in finals]
            ax.errorbar(x[with_ci] + offset, points, yerr=err, fmt="none", ecolor="black", capsize=4)
        for j in have:
            seeds = shown[j].metrics[metric].finals
            # dots beside the error bar, not on it, so both stay readable
            ax.scatter(np.full(len(seeds), x[j] + offset + bar * 0.3), seeds, s=10, color="black", zorder=3)
    ax.set_xticks(
        x, ticks, fontsize=BAR_FONT, rotation=30 if crowded else 0, ha="right" if crowded else "center"
    )
    ax.set_xlim(-0.6, len(shown) - 0.4)
    ax.set_ylim(0, 1.05)
    rules = {m.final_evaluations for c in shown for name in drawn if (m := c.metrics.get(name))}
    ax.set_ylabel(f"final success rate ({final_words(rules.pop() if len(rules) == 1 else None)})")
    ax.set_xlabel(axis_name)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    extra = f"; {dropped} more configurations not drawn" if dropped else ""
    _suptitle(
        fig,
        f"Final {tasks} success by {axis_name}{f' ({paper})' if paper else ''}\n"
        f"n >= {stats.MIN_SEEDS_FOR_CI} seeds: IQM, 95% bootstrap CI; fewer: mean, no CI; "
        f"dots: seeds (their range){extra}",
    )
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path
