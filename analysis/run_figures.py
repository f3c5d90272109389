"""Figures of what happens inside the runs: one test task's sub-goal tree over training (paper Fig. 4d) and
the diagnostics page (why a run does or does not learn: the traversal, the plans, tau_hat). The comparison
figures (success, final success, checks) are in figures.py, whose conventions these follow.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never a display (the report runs on headless machines)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from copilot_ray.keys import (  # noqa: E402
    AGENT_SUBTASK_SUCCESS_LAYER,
    ALGORITHM_TAG,
    DIAG_EUCLIDEAN_ERROR,
    DIAG_Q_MEAN,
    DIAG_SEGMENT_LENGTH_LAYER,
    DIAG_SEGMENT_UNREACHABLE_LAYER,
    DIAG_SUBGOAL_IN_OBSTACLE_LAYER,
    DIAG_SUCCESS_AFTER_FAILED,
    DIAG_SUCCESS_AFTER_REACHED,
    DIAG_TAU_HAT_ERROR,
    PLANNED_COLLISION_FREE,
    REACHED_PLANNED,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    eval_by_action,
)

from .aggregate import ConfigSummary, follows_plan  # noqa: E402
from .figures import DPI, _colors, _select, _suptitle, constant_value, steps_axis, wrap  # noqa: E402
from .load import TreeSnapshot  # noqa: E402


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
    # constrained: the title's lines, the column titles and the panels each get their own room
    fig = plt.figure(figsize=(2.6 * cols + 0.6, 3.4 * rows + 1.2), layout="constrained")
    gs = fig.add_gridspec(2 * rows, cols, height_ratios=[1, 3] * rows)
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
    _suptitle(
        fig,
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
# What a trial must have for a panel's lines to mean what the panel says: TREE, a sub-goal tree (the
# training sub-task panels); PLAN, a plan of its own (HER's and SAC's "plan" is the straight segment
# from start to goal, and their training "sub-task" is the whole task: drawn, they read as a planner's).
TREE, PLAN, ANY = "tree", "plan", "any"

_DIAG_PANELS = (
    (
        "sub-goals inside obstacles",
        (
            (DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "{K}", "-", "layer K"),
            (DIAG_SUBGOAL_IN_OBSTACLE_LAYER + "{K2}", ":", "layer K-2"),
        ),
        TREE,
    ),
    (
        "segments longer than one sub-task can cover",
        (
            (DIAG_SEGMENT_UNREACHABLE_LAYER + "{K}", "-", "layer K"),
            (DIAG_SEGMENT_UNREACHABLE_LAYER + "{K2}", ":", "layer K-2"),
        ),
        TREE,
    ),
    (
        "training sub-task success by layer",
        (
            (AGENT_SUBTASK_SUCCESS_LAYER + "{K}", "-", "layer K"),
            (AGENT_SUBTASK_SUCCESS_LAYER + "{K2}", "--", "layer K-2"),
            (AGENT_SUBTASK_SUCCESS_LAYER + "0", ":", "layer 0"),
        ),
        TREE,
    ),
    (
        "sub-task success after the previous one was...",
        (
            (DIAG_SUCCESS_AFTER_REACHED, "-", "reached"),
            (DIAG_SUCCESS_AFTER_FAILED, ":", "failed"),
        ),
        TREE,
    ),
    ("critic's mean Q", ((DIAG_Q_MEAN, "-", "mean Q"),), ANY),
    (
        "time costs: tau_hat against the agent's steps",
        (
            (DIAG_TAU_HAT_ERROR, "-", "tau_hat, mean |error|"),
            (DIAG_EUCLIDEAN_ERROR, ":", "Euclidean, mean |error|"),
        ),
        TREE,
    ),
    (
        "{tasks}: planned path collision-free / followed",
        (
            (PLANNED_COLLISION_FREE, ":", "plan collision-free"),
            (eval_by_action(REACHED_PLANNED, "deterministic"), "--", "reached (collisions allowed)"),
            (eval_by_action(SUCCESS_PLANNED, "deterministic"), "-", "success"),
        ),
        PLAN,
    ),
    (
        "{tasks} success: deterministic vs sampled actions",
        (
            (eval_by_action(SUCCESS_PLANNED, "deterministic"), "-", "deterministic, planned"),
            (eval_by_action(SUCCESS_PLANNED, "sampled"), "--", "sampled, planned"),
            (eval_by_action(SUCCESS_DIRECT, "sampled"), ":", "sampled, direct"),
        ),
        ANY,
    ),
)

# Each panel's y axis (by its title as written above); a panel not named here shows a rate in [0, 1].
_DIAG_Y_LABELS = {
    "sub-goals inside obstacles": "share of sub-goals",
    "segments longer than one sub-task can cover": "share of segments",
    "critic's mean Q": "mean Q (return units)",
    "time costs: tau_hat against the agent's steps": "env steps (new sub-tasks, before the refit)",
}


def depth_of(trial) -> int:
    layers = [int(k.rsplit("_", 1)[1]) for k in trial.curves if k.startswith(DIAG_SEGMENT_LENGTH_LAYER)]
    return max(layers, default=0)


def plans_of_its_own(trial) -> bool:
    """What its algorithm declares (`follows_plan`: CO-PILOT's tree, SoRB's graph; HER's and SAC's planned
    success is their direct one); for an algorithm this checkout lacks, a sub-goal tree, or a planned
    success that differs from the agent alone's somewhere."""
    if (declared := follows_plan(trial.tags.get(ALGORITHM_TAG, ""))) is not None:
        return declared
    if depth_of(trial) > 0:
        return True
    logged = SUCCESS_PLANNED in trial.curves and SUCCESS_DIRECT in trial.curves
    return logged and not trial.curves_agree(SUCCESS_PLANNED, SUCCESS_DIRECT)


def diagnostic_keys(trial, lines, needs: str) -> list[tuple[str, str]]:
    """(metric, line style) of a panel's lines for one trial: none where the trial lacks what the
    panel needs (a sub-goal tree, a plan of its own), so a flat method's numbers do not pass for a
    planner's."""
    if (needs == TREE and depth_of(trial) == 0) or (needs == PLAN and not plans_of_its_own(trial)):
        return []
    K = depth_of(trial)
    return [(metric.format(K=K, K2=max(K - 2, 1)), style) for metric, style, _ in lines]


def diagnostics(
    configs: list[ConfigSummary], path: Path, notes: list[str] | None = None, tasks: str = "test"
) -> Path | None:
    """Why runs (do not) learn: the `copilot/diag/...` curves and their evaluation counterparts against
    env steps, one panel per question some run has data for (the others are named in `notes`). Returns
    None when no run logged diagnostics."""
    notes = [] if notes is None else notes
    shown, _ = _select(configs)
    trials = [(c, t) for c in shown for t in c.trials if depth_of(t) > 0 or DIAG_Q_MEAN in t.curves]
    if not trials:
        return None

    named = [(title.format(tasks=tasks), lines, needs) for title, lines, needs in _DIAG_PANELS]
    y_label = {title.format(tasks=tasks): _DIAG_Y_LABELS.get(title, "rate") for title, _, _ in _DIAG_PANELS}
    panels = [
        (title, lines, needs)
        for title, lines, needs in named
        if any(k in t.curves for _, t in trials for k, _ in diagnostic_keys(t, lines, needs))
    ]
    empty = [title for title, _, _ in named if title not in {p[0] for p in panels}]
    if empty:
        notes.append(f"{path.name}: panels left out (no run logged their metrics): {'; '.join(empty)}.")
    flat_panels = []
    for title, lines, needs in list(panels):
        curves = [
            t.curves[k] for _, t in trials for k, _ in diagnostic_keys(t, lines, needs) if k in t.curves
        ]
        if (value := constant_value(curves)) is not None:
            panels.remove((title, lines, needs))
            flat_panels.append(f"{title} (every line at {value:g})")
    if flat_panels:
        notes.append(f"{path.name}: panels left out (flat, no signal): {'; '.join(flat_panels)}.")
    flat = sorted({c.label for c, t in trials if depth_of(t) == 0})
    if flat:
        notes.append(
            f"{path.name}: {'; '.join(flat)}: no sub-goal tree, so no lines in the training sub-task "
            "panels (their 'sub-task' is the whole task); in the planned-path panel only where the "
            "method plans (its planned success differs from the agent alone's, as SoRB's graph)."
        )
    if not panels:
        notes.append(f"{path.name}: not drawn: no panel has a line that changes.")
        return None
    drawn = [c for c in shown if any(c is d for d, _ in trials)]
    colors = dict(zip([c.key for c in drawn], _colors(len(drawn)), strict=True))
    cols = min(4, len(panels))
    rows = -(-len(panels) // cols)
    spare = len(panels) < rows * cols
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(4.2 * cols + (0 if spare else 2.4), 3.4 * rows + 0.6),
        squeeze=False,
        layout="constrained",
    )
    for ax, (title, lines, needs) in zip(axes.flat, panels, strict=False):
        for c, t in trials:
            for key, style in diagnostic_keys(t, lines, needs):
                if key not in t.curves:
                    continue
                steps, values = t.curves[key]
                ax.plot(steps, values, style, color=colors[c.key], linewidth=1.3, alpha=0.85)
        for _, style, label in lines:  # the line styles' legend, in black
            ax.plot([], [], style, color="black", label=label)
        ax.set_title(wrap(title, 4.0, 9), fontsize=9)
        ax.set_xlabel("environment steps", fontsize=7)
        ax.set_ylabel(y_label[title], fontsize=7)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
        steps_axis(ax)
        ax.legend(fontsize=6, loc="best")
    for ax in axes.flat[len(panels) :]:
        ax.axis("off")
    handles = [plt.Line2D([], [], color=colors[c.key], linewidth=2) for c in drawn]
    spare = len(panels) < axes.size  # the configurations' legend in the grid's empty slot, else beside it
    where = axes.flat[-1] if spare else fig
    where.legend(
        handles,
        [wrap(c.label, 3.6 if spare else 2.2, 7) for c in drawn],
        fontsize=7,
        loc="center" if spare else "outside right center",
        title="configuration",
    )
    _suptitle(fig, "Diagnostics against environment steps (one line per seed)")
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
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
    fig, axes = plt.subplots(
        1, len(profiles), figsize=(4.2 * len(profiles), 3.8), squeeze=False, layout="constrained"
    )
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
        ax.set_title(wrap(label, 4.0, 9), fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    _suptitle(fig, "Learned time cost against segment length over training")
    fig.savefig(path, dpi=DPI, bbox_inches="tight")
    plt.close(fig)
    return path
