"""PNG figures: success against environment steps, final success per configuration (paper Fig. 2b when
the axis is K), and the evolution of one task's sub-goal tree over training (paper Fig. 4d).

Intervals follow `stats.MIN_SEEDS_FOR_CI`: from 5 seeds on, the IQM with a shaded 95 % bootstrap band
(curves) or error bars (bars); with fewer, the mean with each seed drawn (thin lines, dots: their range)
and no band, so that two seeds never look like a confident estimate."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never a display (the report runs on headless machines)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from copilot_ray.keys import (  # noqa: E402
    AGENT_SUBTASK_SUCCESS_LAYER,
    DIAG_Q_MEAN,
    DIAG_SEGMENT_LENGTH_LAYER,
    DIAG_SEGMENT_UNREACHABLE_LAYER,
    DIAG_SUBGOAL_IN_OBSTACLE_LAYER,
    DIAG_SUCCESS_AFTER_FAILED,
    DIAG_SUCCESS_AFTER_REACHED,
    EVAL_MASTERED,
    EVAL_RETURN,
    EVAL_SUCCESS,
    PLANNED_COLLISION_FREE,
    REACHED_PLANNED,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    eval_by_action,
)

from . import stats  # noqa: E402
from .aggregate import ConfigSummary, CurveSummary  # noqa: E402
from .load import TreeSnapshot  # noqa: E402

TITLES = {
    EVAL_SUCCESS: "each method's headline (CO-PILOT, SoRB: along their plans; SAC, HER, PPO: agent alone)",
    SUCCESS_PLANNED: "agent following the planner's finest path",
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
    if len(configs) <= MAX_CURVES:
        return configs, 0

    def score(c):
        m = c.metrics.get(EVAL_SUCCESS) or c.metrics.get(SUCCESS_PLANNED)
        return m.final.point if m and np.isfinite(m.final.point) else -1.0

    keep = set(id(c) for c in sorted(configs, key=score, reverse=True)[:MAX_CURVES])
    return [c for c in configs if id(c) in keep], len(configs) - MAX_CURVES


def success_curves(
    configs: list[ConfigSummary], axis_name: str, path: Path, metrics: tuple[str, ...] = PLANNED_AND_DIRECT
) -> Path:
    """One panel per metric (planned and direct; `BY_METHOD`: the common success, paper Fig. 4a), one
    colour per configuration: IQM over seeds and its 95 % bootstrap band from 5 seeds on, else the mean
    and each seed as a thin line (no band). Solid where every seed of the configuration has data, dashed
    where only some do (seeds are never extrapolated past their last evaluation)."""
    shown, dropped = _select(configs)
    colors = _colors(len(shown))
    fig, axes = plt.subplots(1, len(metrics), figsize=(6 * len(metrics) + 1, 4.5), sharey=True, squeeze=False)
    axes = axes[0]
    for ax, metric in zip(axes, metrics, strict=True):
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
        ax.set_title(f"{metric.split('/')[-1]}: {TITLES[metric]}", fontsize=10)
        ax.set_xlabel("environment steps")
        ylabel, ylim = Y_AXES.get(metric, SUCCESS_AXIS)
        if ylim is not None:
            ax.set_ylim(*ylim)
        ax.grid(alpha=0.3)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))
    axes[0].set_ylabel(Y_AXES.get(metrics[0], SUCCESS_AXIS)[0])
    handles, labels = axes[0].get_legend_handles_labels()
    if not handles:
        handles, labels = axes[1].get_legend_handles_labels()
    if handles:
        fig.legend(
            handles, labels, loc="center left", bbox_to_anchor=(0.83, 0.5), fontsize=8, title=axis_name
        )
    note = INTERVAL_NOTE + "; dashed: not all seeds have reached this step"
    if dropped:
        note += f"; {dropped} more configurations not drawn"
    what = {RETURN: "Return", MASTERED: "Mastered track distributions"}.get(metrics, "Success")
    fig.suptitle(f"{what} against environment steps, by {axis_name}\n{note}", fontsize=10)
    fig.tight_layout(rect=(0, 0, 0.83 if handles else 1, 1))
    fig.savefig(path, dpi=DPI, bbox_inches="tight")  # long legend labels sit right of the axes
    plt.close(fig)
    return path


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


def final_success(
    configs: list[ConfigSummary], axis_name: str, path: Path, metrics: tuple[str, ...] = PLANNED_AND_DIRECT
) -> Path:
    """Grouped bars (one per metric: planned and direct, or `BY_METHOD`'s common success, paper
    Fig. 2a) of final success, each seed as a dot: the IQM with its 95 % CI from 5 seeds on, else the
    mean without error bars (the dots are the range)."""
    shown, dropped = _select(configs)
    x = np.arange(len(shown))
    width = 0.76 / len(metrics)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.9 * len(shown) + 3), 4.5))
    palette = ("tab:blue", "tab:orange", "tab:green")
    for i, metric in enumerate(metrics):
        offset, color = (i - (len(metrics) - 1) / 2) * width, palette[i % len(palette)]
        vals = np.array([c.metrics[metric].final.point if metric in c.metrics else np.nan for c in shown])
        ax.bar(x + offset, np.nan_to_num(vals), width, color=color, alpha=0.8, label=metric.split("/")[-1])
        with_ci = [j for j, c in enumerate(shown) if metric in c.metrics and c.metrics[metric].final.has_ci]
        if with_ci:  # error bars only where they are a CI
            finals = [shown[j].metrics[metric].final for j in with_ci]
            err = np.clip([[f.point - f.low for f in finals], [f.high - f.point for f in finals]], 0, None)
            points = [f.point for f in finals]
            ax.errorbar(x[with_ci] + offset, points, yerr=err, fmt="none", ecolor="black", capsize=4)
        for j, c in enumerate(shown):
            seeds = [t.curves[metric][1][-1] for t in c.trials if metric in t.curves]
            # dots beside the error bar, not on it, so both stay readable
            ax.scatter(np.full(len(seeds), x[j] + offset + width * 0.3), seeds, s=10, color="black", zorder=3)
    ax.set_xticks(
        x,
        [f"{c.label}\n(n = {c.n_seeds})" for c in shown],
        rotation=30 if len(shown) > 6 else 0,
        ha="right" if len(shown) > 6 else "center",
    )
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("final success rate (last evaluation)")
    ax.set_xlabel(axis_name)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    paper = " (paper Fig. 2b)" if axis_name == "K" else " (paper Fig. 2a)" if metrics == BY_METHOD else ""
    extra = f"; {dropped} more configurations not drawn" if dropped else ""
    ax.set_title(
        f"Final success by {axis_name}{paper}\nn >= {stats.MIN_SEEDS_FOR_CI} seeds: IQM, 95% bootstrap CI; "
        f"fewer: mean, no CI\ndots: seeds (their range){extra}",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def tree_figure_layers(depth: int) -> list[int]:
    """The layers Fig. 4d shows: 2, 3 and 4 as in the paper, or the deepest three of a shallower tree."""
    return [2, 3, 4] if depth >= 4 else list(range(max(1, depth - 2), depth + 1))


def subgoal_tree_evolution(snapshots: list[TreeSnapshot], task: int, title: str, path: Path) -> Path:
    """Paper Fig. 4d: rows = layers 2, 3, 4 (see `tree_figure_layers`), columns = training stages; each
    panel shows the layer's planned path for one fixed test task over the maze (start red, goal blue)
    and, above it, the agent's measured steps per sub-task along that path (grey = not reached)."""
    from copilot_ray.envs.maze import load_layout, render_maze

    depth = snapshots[0].depth
    layers = tree_figure_layers(depth)
    layout_name = snapshots[0].layout or "four-rooms"
    try:
        layout = load_layout(layout_name)
    except (ValueError, OSError):  # a user's layout file not present here: draw the paths on an empty square
        layout = load_layout("empty")
        title += f" (layout {layout_name!r} not found here; drawn without walls)"
    ymax = max(
        1, max(int(s.subtask_steps[task, k, : 2**k].max(initial=0)) for s in snapshots for k in layers)
    )
    rows, cols = len(layers), len(snapshots)
    fig = plt.figure(figsize=(2.6 * cols + 0.6, 3.4 * rows + 0.8))
    gs = fig.add_gridspec(2 * rows, cols, height_ratios=[1, 3] * rows, hspace=0.35, wspace=0.1)
    for r, k in enumerate(layers):
        for c, snap in enumerate(snapshots):
            steps = snap.subtask_steps[task, k, : 2**k]
            reached = snap.subtask_reached[task, k, : 2**k]
            ax_h = fig.add_subplot(gs[2 * r, c])
            ax_h.bar(
                np.arange(len(steps)),
                np.clip(steps, 0, None),
                color=np.where(reached, "tab:green", "0.6"),
                width=0.85,
            )
            ax_h.set_ylim(0, ymax * 1.05)
            ax_h.set_xticks([])
            ax_h.tick_params(labelsize=6)
            if c:
                ax_h.set_yticklabels([])
            if r == 0:
                ax_h.set_title(f"iter {snap.iteration}\n{snap.env_steps:,} env steps", fontsize=8)
            ax_m = fig.add_subplot(gs[2 * r + 1, c])
            pts = snap.layer_path(task, k)
            if snap.region is not None:  # the walls the planner saw, in the env's own units
                _draw_walls_and_path(ax_m, snap, pts)
            else:  # older snapshots: the 1 x 1 maze by its layout name
                img = render_maze(layout, paths=[pts], agent=pts[0], goal=pts[-1], size=240)
                ax_m.imshow(img, extent=(0, 1, 0, 1), interpolation="nearest")
            ax_m.set_xticks([])
            ax_m.set_yticks([])
            if c == 0:
                ax_m.set_ylabel(f"layer {k}\n({2**k} sub-tasks)", fontsize=9)
    fig.suptitle(
        f"{title}\nsub-goal paths of test task {task} (start: red, goal: blue); "
        "bars: agent steps per sub-task (grey: not reached)",
        fontsize=9,
    )
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path


def _draw_walls_and_path(ax, snap: TreeSnapshot, pts: np.ndarray) -> None:
    """The obstacle boxes (grey) over the region, the path (orange, its x-y plane), start red, goal blue."""
    from matplotlib.patches import Rectangle

    (x0, y0), (x1, y1) = snap.region
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor="white", edgecolor="black", linewidth=1))
    for lo, hi in zip(snap.walls_lo, snap.walls_hi, strict=True):
        ax.add_patch(Rectangle(tuple(lo), *(hi - lo), facecolor="0.35", edgecolor="none"))
    ax.plot(pts[:, 0], pts[:, 1], "-o", color="tab:orange", markersize=2, linewidth=1.2)
    ax.plot(*pts[0, :2], "o", color="red", markersize=5)
    ax.plot(*pts[-1, :2], "o", color="blue", markersize=5)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")


# ---------------------------------------------------------------------------------------------- diagnostics
# One panel per question, one colour per configuration, one line per seed. (metric, line style, label);
# {K} / {K2} in a metric: the run's tree depth K / max(K - 2, 1).
_DIAG_PANELS = (
    (
        "sub-goals inside obstacles",
        (
            (DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "{K}", "-", "layer K"),
            (DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "{K2}", ":", "layer K-2"),
        ),
    ),
    (
        "segments longer than one sub-task can cover",
        (
            (DIAG_SEGMENT_UNREACHABLE_LAYER + "{K}", "-", "layer K"),
            (DIAG_SEGMENT_UNREACHABLE_LAYER + "{K2}", ":", "layer K-2"),
        ),
    ),
    (
        "training sub-task success by layer",
        (
            (AGENT_SUBTASK_SUCCESS_LAYER + "{K}", "-", "layer K"),
            (AGENT_SUBTASK_SUCCESS_LAYER + "{K2}", "--", "layer K-2"),
            (AGENT_SUBTASK_SUCCESS_LAYER + "0", ":", "layer 0"),
        ),
    ),
    (
        "sub-task success after the previous one was...",
        (
            (DIAG_SUCCESS_AFTER_REACHED, "-", "reached"),
            (DIAG_SUCCESS_AFTER_FAILED, ":", "failed"),
        ),
    ),
    ("critic's mean Q", ((DIAG_Q_MEAN, "-", "mean Q"),)),
    (
        "test: planned path collision-free / followed",
        (
            (PLANNED_COLLISION_FREE, ":", "plan collision-free"),
            (eval_by_action(REACHED_PLANNED, "deterministic"), "--", "reached (collisions allowed)"),
            (eval_by_action(SUCCESS_PLANNED, "deterministic"), "-", "success"),
        ),
    ),
    (
        "test success: deterministic vs sampled actions",
        (
            (eval_by_action(SUCCESS_PLANNED, "deterministic"), "-", "deterministic, planned"),
            (eval_by_action(SUCCESS_PLANNED, "sampled"), "--", "sampled, planned"),
            (eval_by_action(SUCCESS_DIRECT, "sampled"), ":", "sampled, direct"),
        ),
    ),
)


def depth_of(trial) -> int:
    layers = [int(k.rsplit("_", 1)[1]) for k in trial.curves if k.startswith(DIAG_SEGMENT_LENGTH_LAYER)]
    return max(layers, default=0)


def diagnostics(configs: list[ConfigSummary], path: Path) -> Path | None:
    """Why runs (do not) learn: the `copilot/diag/...` curves and their evaluation counterparts against
    env steps. Returns None when no run logged diagnostics."""
    shown, _ = _select(configs)
    trials = [(c, t) for c in shown for t in c.trials if depth_of(t) > 0 or DIAG_Q_MEAN in t.curves]
    if not trials:
        return None
    colors = dict(zip([c.key for c in shown], _colors(len(shown)), strict=True))
    cols = 4
    rows = -(-len(_DIAG_PANELS) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, (title, lines) in zip(axes.flat, _DIAG_PANELS, strict=False):
        for c, t in trials:
            K = depth_of(t)
            for metric, style, _ in lines:
                key = metric.format(K=K, K2=max(K - 2, 1))
                if key not in t.curves:
                    continue
                steps, values = t.curves[key]
                ax.plot(steps, values, style, color=colors[c.key], linewidth=1.3, alpha=0.85)
        for _, style, label in lines:  # the line styles' legend, in black
            ax.plot([], [], style, color="black", label=label)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("environment steps", fontsize=7)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 3))
        ax.legend(fontsize=6, loc="best")
    for ax in axes.flat[len(_DIAG_PANELS) :]:
        ax.axis("off")
    handles = [plt.Line2D([], [], color=colors[c.key], linewidth=2) for c in shown]
    axes.flat[-1].legend(handles, [c.label for c in shown], fontsize=7, loc="center", title="configuration")
    fig.suptitle("Diagnostics against environment steps (one line per seed)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def tau_hat_profiles(
    profiles: list[tuple[str, list[TreeSnapshot]]], reachable: float | None, path: Path
) -> Path | None:
    """tau_hat (the learned time cost, distance units) against segment length at a few points of
    training, one panel per configuration; the diagonal is the Euclidean cost it starts from."""
    profiles = [(label, [s for s in snaps if s.tau_hat is not None]) for label, snaps in profiles]
    profiles = [(label, snaps) for label, snaps in profiles if snaps]
    if not profiles:
        return None
    fig, axes = plt.subplots(1, len(profiles), figsize=(4.2 * len(profiles), 3.6), squeeze=False)
    for ax, (label, snaps) in zip(axes[0], profiles, strict=True):
        top = max(float(np.max(s.tau_hat_length)) for s in snaps)
        ax.plot([0, top], [0, top], color="0.6", linewidth=1, label="Euclidean")
        shades = plt.get_cmap("viridis")(np.linspace(0.1, 0.9, len(snaps)))
        for s, shade in zip(snaps, shades, strict=True):
            ax.plot(s.tau_hat_length, s.tau_hat, "o-", color=shade, label=f"{s.env_steps:,} env steps")
        if reachable is not None:
            ax.axvline(reachable, color="tab:red", linestyle=":", linewidth=1, label="one sub-task's reach")
        ax.set_xlabel("segment length")
        ax.set_ylabel("tau_hat (distance units)")
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Learned time cost against segment length over training", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path
