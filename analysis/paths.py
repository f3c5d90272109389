"""The planners' figures (the paper's Fig. 4b/4c): every run that logged ``paths/*`` (RRT*, SGT-PG,
CO-PILOT's finest paths) in one table and one figure, per agent (env) and method (algorithm).

Table: per (algorithm, env), the mean over seeds of each metric's last value, with the seeds' range, and
the method's privileges (copilot_ray.privileges; "-": runs older than the tag).
Figure: one column per env, rows success / length vs RRT* / collision checks vs RRT*, one line per method
(mean over seeds at the env steps every seed reached), against env steps on a log axis: for the
planner-only methods their collision checks (what they report as env steps), for CO-PILOT real env
steps. RRT* plans each task once, so its "curve" is its running figures over the tasks planned so far and
its last point is the reference every ratio divides by.
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
    ALGORITHM_TAG,
    ENV_TAG,
    PATH_CHECKS_VS_RRT,
    PATH_COLLISION_CHECKS,
    PATH_LENGTH,
    PATH_LENGTH_VS_RRT,
    PATH_SUCCESS,
    PATH_SUCCESS_VS_RRT,
)

from .aggregate import privileges_label  # noqa: E402
from .load import Trial  # noqa: E402

COLUMNS = {
    PATH_SUCCESS: "success",
    PATH_SUCCESS_VS_RRT: "success / RRT*",
    PATH_LENGTH: "length",
    PATH_LENGTH_VS_RRT: "length / RRT*",
    PATH_COLLISION_CHECKS: "collision checks",
    PATH_CHECKS_VS_RRT: "checks / RRT*",
}
PANELS = (PATH_SUCCESS, PATH_LENGTH_VS_RRT, PATH_CHECKS_VS_RRT)
PANEL_TITLES = {
    PATH_SUCCESS: "success (collision-free path to the goal)",
    PATH_LENGTH_VS_RRT: "path length / RRT*'s (tasks both solved)",
    PATH_CHECKS_VS_RRT: "collision checks / RRT*'s",
}


def path_trials(trials: list[Trial]) -> list[Trial]:
    """The usable trials that logged the paths' figures."""
    return [t for t in trials if t.usable and PATH_SUCCESS in t.curves]


def _groups(trials: list[Trial]) -> dict[tuple[str, str], list[Trial]]:
    out: dict[tuple[str, str], list[Trial]] = {}
    for t in trials:
        out.setdefault((t.tags.get(ALGORITHM_TAG, "?"), t.tags.get(ENV_TAG, "?")), []).append(t)
    return dict(sorted(out.items(), key=lambda kv: (kv[0][1], kv[0][0])))


def path_frame(trials: list[Trial]) -> pd.DataFrame:
    """One row per (env, algorithm): seeds and each metric's last value, mean [min, max] over seeds."""
    rows = []
    for (algorithm, env), group in _groups(path_trials(trials)).items():
        row: dict[str, object] = {"env": env, "algorithm": algorithm, "n_seeds": len(group)}
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


def markdown(frame: pd.DataFrame) -> str:
    """The table with mean [min, max] cells (a single seed: just its value)."""
    names = list(COLUMNS.values())
    header = ["env", "algorithm", "seeds", *names, "env steps (planners: checks)", "privileges"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    for _, r in frame.iterrows():
        cells = [str(r["env"]), str(r["algorithm"]), str(r["n_seeds"])]
        for name in names:
            cells.append(_cell(r[name], r[f"{name} min"], r[f"{name} max"], big=name == "collision checks"))
        cells.append(f"{r['env steps']:,.0f}")
        cells.append(str(r["privileges"]))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _cell(mean: float, low: float, high: float, big: bool = False) -> str:
    if not math.isfinite(mean):
        return "-"
    fmt = (lambda v: f"{v:,.0f}") if big else (lambda v: f"{v:.2f}")
    return fmt(mean) if low == high else f"{fmt(mean)} [{fmt(low)}, {fmt(high)}]"


def _mean_curve(group: list[Trial], key: str) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean over seeds on the first seed's steps, up to where every seed has data (no extrapolation)."""
    curves = [t.curves[key] for t in group if key in t.curves and len(t.curves[key][0])]
    if not curves:
        return None
    end = min(c[0][-1] for c in curves)
    grid = curves[0][0][curves[0][0] <= end]
    values = np.mean([np.interp(grid, steps, vals) for steps, vals in curves], axis=0)
    return grid, values


def path_figure(trials: list[Trial], path: Path) -> Path | None:
    """Fig. 4a-c for each agent: success, length / RRT*'s and checks / RRT*'s against env steps."""
    groups = _groups(path_trials(trials))
    if not groups:
        return None
    envs = sorted({env for _, env in groups})
    algorithms = sorted({algorithm for algorithm, _ in groups})
    colors = dict(zip(algorithms, plt.get_cmap("tab10").colors, strict=False))
    fig, axes = plt.subplots(
        len(PANELS), len(envs), figsize=(4.2 * len(envs), 3.0 * len(PANELS)), squeeze=False, sharex="col"
    )
    for col, env in enumerate(envs):
        for row, key in enumerate(PANELS):
            ax = axes[row][col]
            for algorithm in algorithms:
                group = groups.get((algorithm, env))
                curve = _mean_curve(group, key) if group else None
                if curve is None:
                    continue
                steps, values = curve
                ax.plot(
                    steps,
                    values,
                    marker="o" if len(steps) < 3 else None,
                    ms=4,
                    color=colors[algorithm],
                    label=f"{algorithm} ({len(group)} seed{'s' if len(group) > 1 else ''})",
                )
            if key != PATH_SUCCESS:
                ax.axhline(1.0, color="grey", lw=0.8, ls=":")
                ax.set_yscale("log")
            ax.set_xscale("log")
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(env)
            if col == 0:
                ax.set_ylabel(PANEL_TITLES[key], fontsize=8)
            if row == len(PANELS) - 1:
                ax.set_xlabel("env steps (planners: collision checks)")
        axes[0][col].legend(fontsize=7)
    fig.suptitle("Planners on the same test tasks (paper Fig. 4a-c): means over seeds")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
