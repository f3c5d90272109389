"""Numpy rasterisation of a maze, the agent, the goal and sub-goal paths (no plotting library needed)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .layouts import Layout, load_layout

BACKGROUND = (255, 255, 255)
OBSTACLE = (60, 60, 70)
AGENT = (220, 40, 40)
GOAL = (40, 110, 230)
PATH_COLORS = [(40, 170, 80), (240, 150, 20), (150, 60, 200), (20, 180, 190), (200, 60, 140)]


class Canvas:
    """A square uint8 RGB image over the unit square; y points up, as in the maze."""

    def __init__(self, size: int):
        self.size = int(size)
        self.image = np.empty((self.size, self.size, 3), dtype=np.uint8)
        self.image[:] = BACKGROUND
        # Pixel centres in unit-square coordinates.
        centres = (np.arange(self.size) + 0.5) / self.size
        self._xs, self._ys = centres, 1.0 - centres

    def _window(self, lo_xy: np.ndarray, hi_xy: np.ndarray) -> tuple[slice, slice]:
        c0 = int(np.clip(np.floor(lo_xy[0] * self.size), 0, self.size))
        c1 = int(np.clip(np.ceil(hi_xy[0] * self.size) + 1, 0, self.size))
        r0 = int(np.clip(np.floor((1.0 - hi_xy[1]) * self.size), 0, self.size))
        r1 = int(np.clip(np.ceil((1.0 - lo_xy[1]) * self.size) + 1, 0, self.size))
        return slice(r0, r1), slice(c0, c1)

    def cells(self, grid: np.ndarray, color: tuple[int, int, int]) -> None:
        rows, cols = grid.shape
        r = np.minimum((np.arange(self.size) * rows) // self.size, rows - 1)
        c = np.minimum((np.arange(self.size) * cols) // self.size, cols - 1)
        self.image[grid[r][:, c]] = color

    def disc(self, center: np.ndarray, radius_px: float, color: tuple[int, int, int]) -> None:
        center = np.asarray(center, dtype=np.float64)[:2]
        rad = radius_px / self.size
        rows, cols = self._window(center - rad, center + rad)
        dx = self._xs[cols][None, :] - center[0]
        dy = self._ys[rows][:, None] - center[1]
        self.image[rows, cols][dx**2 + dy**2 <= rad**2] = color

    def segment(self, p: np.ndarray, q: np.ndarray, width_px: float, color: tuple[int, int, int]) -> None:
        p, q = np.asarray(p, dtype=np.float64)[:2], np.asarray(q, dtype=np.float64)[:2]
        half = 0.5 * max(width_px, 1.0) / self.size
        rows, cols = self._window(np.minimum(p, q) - half, np.maximum(p, q) + half)
        px = self._xs[cols][None, :] - p[0]
        py = self._ys[rows][:, None] - p[1]
        d = q - p
        t = np.clip((px * d[0] + py * d[1]) / max(float(d @ d), 1e-18), 0.0, 1.0)
        dist2 = (px - t * d[0]) ** 2 + (py - t * d[1]) ** 2
        self.image[rows, cols][dist2 <= half**2] = color


def render_maze(
    layout_or_env: Any,
    agent: np.ndarray | None = None,
    goal: np.ndarray | None = None,
    paths: Sequence[np.ndarray] = (),
    size: int = 256,
    goal_radius: float | None = None,
    agent_geometry: Any = None,
) -> np.ndarray:
    """uint8 [size, size, 3]: the maze, optional sub-goal paths ([P, goal_dim] each), goal and agent.

    `layout_or_env` is a Layout, a layout name/path, or a maze env (whose layout, agent geometry and
    success radius are then used).
    """
    env = getattr(layout_or_env, "unwrapped", None)
    if env is not None and hasattr(env, "layout"):
        layout: Layout = env.layout
        agent_geometry = agent_geometry or env.agent_geometry
        goal_radius = env.success_radius if goal_radius is None else goal_radius
    else:
        layout = load_layout(layout_or_env)
    canvas = Canvas(size)
    canvas.cells(layout.grid, OBSTACLE)
    for k, path in enumerate(paths):
        pts = np.asarray(path, dtype=np.float64).reshape(len(path), -1)
        color = PATH_COLORS[k % len(PATH_COLORS)]
        for p, q in zip(pts[:-1], pts[1:], strict=True):
            canvas.segment(p, q, width_px=max(1.0, size / 200), color=color)
        for p in pts:
            canvas.disc(p, radius_px=max(1.5, size / 120), color=color)
    if goal is not None:
        radius_px = max(3.0, (goal_radius or 0.025) * size)
        canvas.disc(np.asarray(goal), radius_px=radius_px, color=GOAL)
    if agent is not None:
        if agent_geometry is not None:
            agent_geometry.draw(canvas, np.asarray(agent), AGENT)
        else:
            canvas.disc(np.asarray(agent), radius_px=max(2.0, size / 80), color=AGENT)
    return canvas.image
