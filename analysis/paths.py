"""The planners' figures (the paper's Fig. 4b/4c): every run that logged ``paths/*`` (RRT*, SGT-PG,
CO-PILOT's finest paths) in one table and one figure, per env and configuration (never two configurations
pooled as seeds: CO-PILOT's variants, or one variant on two layouts, are rows of their own).

Table: per (env, method), the mean over seeds of each metric's last value, with the seeds' range, and
the method's privileges (copilot_ray.privileges; "-": runs older than the tag).
Figure: one column per env, rows success / length vs RRT* / collision checks vs RRT* (a row no run has
data for is left out: the ratios need an RRT* reference), one line per method (mean over seeds at the env
steps every seed reached), against env steps: for the planner-only methods their collision checks (what
they report as env steps), for CO-PILOT real env steps. RRT* plans each task once, so its "curve" is its
running figures over the tasks planned so far and its last point is the reference every ratio divides by.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from copilot_ray.keys import (  # noqa: E402
    PATH_CHECKS_VS_RRT,
    PATH_COLLISION_CHECKS,
    PATH_LENGTH,
    PATH_LENGTH_VS_RRT,
    PATH_SUCCESS,
    PATH_SUCCESS_VS_RRT,
)

from .aggregate import ConfigSummary, privileges_label  # noqa: E402
from .figures import constant_value, steps_axis, wrap  # noqa: E402
from .load import Trial  # noqa: E402
from .tables import Table  # noqa: E402

COLUMNS = {
    PATH_SUCCESS: "success",
    PATH_SUCCESS_VS_RRT: "success / RRT*",
    PATH_LENGTH: "length",
    PATH_LENGTH_VS_RRT: "length / RRT*",
    PATH_COLLISION_CHECKS: "collision checks",
    PATH_CHECKS_VS_RRT: "checks / RRT*",
}
PANELS = (PATH_SUCCESS, PATH_LENGTH_VS_RRT, PATH_CHECKS_VS_RRT)
PLANNER_ONLY = {
    "rrt_star": "RRT*",
    "sgt_pg": "SGT-PG",
    "next": "NEXT",
}  # algorithm tag -> name; their env steps are checks
PANEL_TITLES = {
    PATH_SUCCESS: "success (collision-free path to the goal)",
    PATH_LENGTH_VS_RRT: "path length / RRT*'s (tasks both solved)",
    PATH_CHECKS_VS_RRT: "collision checks / RRT*'s",
}


def path_trials(trials: list[Trial]) -> list[Trial]:
    """The usable trials that logged the paths' figures."""
    return [t for t in trials if t.usable and PATH_SUCCESS in t.curves]


def _groups(configs: list[ConfigSummary]) -> dict[tuple[str, str], tuple[ConfigSummary, list[Trial]]]:
    """(env, method) -> (configuration, its trials with paths), by env then method."""
    out = {}
    for c in configs:
        trials = path_trials(c.trials)
        if trials:
            out[(c.env, c.method)] = (c, trials)
    return dict(sorted(out.items()))


def path_frame(configs: list[ConfigSummary]) -> pd.DataFrame:
    """One row per (env, method): seeds and each metric's last value, its mean, min and max over seeds."""
    rows = []
    for (env, method), (c, group) in _groups(configs).items():
        row: dict[str, object] = {
            "env": env,
            "algorithm": c.algorithm,
            "method": method,
            "configuration": c.label,
            "n_seeds": len(group),
        }
        for key, name in COLUMNS.items():
            finals = [_final(t, key) for t in group]
            finals = [v for v in finals if math.isfinite(v)]
            row[name] = float(np.mean(finals)) if finals else math.nan
            row[f"{name} min"] = float(np.min(finals)) if finals else math.nan
            row[f"{name} max"] = float(np.max(finals)) if finals else math.nan
        row["env steps"] = float(np.mean([t.curves[PATH_SUCCESS][0][-1] for t in group]))
        row["privileges"] = privileges_label(group)
        rows.append(row)
    return pd.DataFrame(rows)


def _final(trial: Trial, key: str) -> float:
    """`key` at the trial's last evaluation; NaN when it was undefined there (an undefined figure, e.g. a
    length with no successful path, is not logged, so an older value would otherwise pass for the last)."""
    steps, values = trial.curves.get(key, ((), ()))
    last = trial.curves[PATH_SUCCESS][0][-1]
    return float(values[-1]) if len(steps) and steps[-1] == last else math.nan


def table(frame: pd.DataFrame) -> Table:
    """The table with "mean (range min-max)" cells (a single seed: just its value; an unlabelled
    "[min, max]" would read as the report's confidence intervals); columns no row has a value
    in (the ratios without an RRT* reference) are left out."""
    names = [n for n in COLUMNS.values() if frame[n].notna().any()]
    out = Table(["env", "method", "seeds", *names, "env steps (planners: checks)", "privileges"])
    for _, r in frame.iterrows():
        cells = [str(r["env"]), str(r["method"]), str(r["n_seeds"])]
        for name in names:
            cells.append(_cell(r[name], r[f"{name} min"], r[f"{name} max"], big=name == "collision checks"))
        cells.append(f"{r['env steps']:,.0f}")
        cells.append(str(r["privileges"]))
        out.rows.append(cells)
    return out


def markdown(frame: pd.DataFrame) -> str:
    return table(frame).markdown()


def _cell(mean: float, low: float, high: float, big: bool = False) -> str:
    if not math.isfinite(mean):
        return "-"
    fmt = (lambda v: f"{v:,.0f}") if big else (lambda v: f"{v:.2f}")
    return fmt(mean) if low == high else f"{fmt(mean)} (range {fmt(low)}-{fmt(high)})"


def _seed_curves(group: list[Trial], key: str) -> list[tuple[np.ndarray, np.ndarray]]:
    return [t.curves[key] for t in group if key in t.curves and len(t.curves[key][0])]


def _mean_curve(group: list[Trial], key: str) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean over seeds at the seeds' evaluated steps inside the window every seed covers (from the latest
    first evaluation to the earliest last one: no seed is extrapolated); None without such a window."""
    curves = _seed_curves(group, key)
    if not curves:
        return None
    start, end = max(c[0][0] for c in curves), min(c[0][-1] for c in curves)
    if start > end:
        return None
    grid = np.unique(np.concatenate([c[0][(c[0] >= start) & (c[0] <= end)] for c in curves]))
    values = np.mean([np.interp(grid, steps, vals) for steps, vals in curves], axis=0)
    return grid, values


def _seeds_label(method: str, groups, envs: list[str]) -> str:
    """'copilot (variant=continue): 2 seeds', or the seeds per env when they differ."""
    seeds = {env: len(groups[(env, method)][1]) for env in envs if (env, method) in groups}
    if len(set(seeds.values())) == 1:
        n = next(iter(seeds.values()))
        return f"{method}: {n} seed{'s' if n > 1 else ''}"
    return f"{method}: " + ", ".join(f"{n} on {env}" for env, n in seeds.items())


def _ratio_axis(ax) -> None:
    """A log y axis for ratios to RRT*'s that reads 0.5, 1, 2, 5 (not 2 x 10^0)."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_yscale("log")
    low, high = ax.get_ylim()
    decades = np.log10(high / low) if low > 0 else 10.0
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0) if decades <= 2.5 else (1.0,), numticks=8))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def path_figure(
    configs: list[ConfigSummary], path: Path, paper: str = "", notes: list[str] | None = None
) -> Path | None:
    """Success, length / RRT*'s and checks / RRT*'s against env steps, one column per env; the rows no
    method has data for are left out (and named in `notes`). `paper`: the paper's figure, or ""."""
    notes = [] if notes is None else notes
    groups = _groups(configs)
    if not groups:
        return None
    panels = [k for k in PANELS if any(_seed_curves(g, k) for _, g in groups.values())]
    for k in PANELS:
        if k not in panels:
            notes.append(
                f"{path.name}: no '{PANEL_TITLES[k]}' row: no run logged {k} (it needs RRT*'s reference)."
            )
    for k in list(panels):
        value = constant_value([c for _, g in groups.values() for c in _seed_curves(g, k)])
        if value is not None:
            panels.remove(k)
            notes.append(
                f"{path.name}: no '{PANEL_TITLES[k]}' row: every method's curve is flat at {value:g} "
                "(no signal to draw; the value is in the table)."
            )
    if not panels:
        return None
    envs = sorted({env for env, _ in groups})
    methods = sorted({method for _, method in groups})
    # the planner-only methods report collision checks as their env steps
    planners = sorted({c.algorithm for c, _ in groups.values() if c.algorithm in PLANNER_ONLY})
    xlabel = (
        f"env steps ({', '.join(PLANNER_ONLY[a] for a in planners)}: collision checks)"
        if planners
        else "env steps"
    )
    colors = dict(zip(methods, plt.get_cmap("tab10").colors, strict=False))
    fig, axes = plt.subplots(
        len(panels),
        len(envs),
        figsize=(4.4 * len(envs) + 0.8, 3.0 * len(panels) + 0.9),
        squeeze=False,
        sharex="col",
        layout="constrained",
    )
    for col, env in enumerate(envs):
        steps_seen = [t.curves[PATH_SUCCESS][0] for (e, _), (_, g) in groups.items() if e == env for t in g]
        lo = min(float(s[s > 0].min()) for s in steps_seen if (s > 0).any()) if steps_seen else 1.0
        hi = max(float(s.max()) for s in steps_seen) if steps_seen else 1.0
        log = hi / max(lo, 1.0) > 30  # planners' checks and CO-PILOT's env steps: decades apart
        for row, key in enumerate(panels):
            ax = axes[row][col]
            for method in methods:
                entry = groups.get((env, method))
                if entry is None or not _seed_curves(entry[1], key):
                    continue
                curve = _mean_curve(entry[1], key)
                if curve is None:  # the seeds' evaluations do not overlap: each seed, no mean
                    for steps, values in _seed_curves(entry[1], key):
                        ax.plot(steps, values, marker="o", ms=3, lw=0.8, color=colors[method])
                    if key == PATH_SUCCESS:
                        notes.append(
                            f"{path.name}: {method} on {env}: its seeds' evaluations share no env steps "
                            "(one still running?): each seed drawn, no mean."
                        )
                    continue
                steps, values = curve
                ax.plot(
                    steps,
                    values,
                    marker="o" if len(steps) < 3 else None,
                    ms=4,
                    color=colors[method],
                )
            if key != PATH_SUCCESS:
                ax.axhline(1.0, color="grey", lw=0.8, ls=":")
                _ratio_axis(ax)
            steps_axis(ax, log=log)
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(wrap(env, 4.0, 10), fontsize=10)
            if col == 0:
                ax.set_ylabel(wrap(PANEL_TITLES[key], 2.6, 8), fontsize=8)
            if row == len(panels) - 1:
                ax.set_xlabel(xlabel, fontsize=8)
    # One legend for the figure (inside a panel it hides lines): each method and its seeds per env.
    handles = [plt.Line2D([], [], color=colors[m], linewidth=2) for m in methods]
    fig.legend(
        handles,
        [wrap(_seeds_label(m, groups, envs), 3.2, 8) for m in methods],
        loc="outside right center",
        fontsize=8,
        title="method (seeds)",
    )
    what = "Planners' paths" if planners else "Planned paths"
    title = f"{what} on the test tasks" + (f" ({paper})" if paper else "") + ": means over seeds"
    fig.suptitle(wrap(title, fig.get_figwidth() * 0.95, 10), fontsize=10)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return path
