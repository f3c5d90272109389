"""The 1 x 1 maze family: layouts, exact collision geometry, agents, task sets, rendering, the env."""

from .agents import AgentGeometry, PointMass
from .env import AGENTS, DEFAULT_LAYOUT, DEFAULT_SPEED, DEFAULTS, GoalMazeEnv, shortest_path_lengths
from .geometry import Obstacles, VisibilityGraph, merge_cells
from .layouts import Layout, LayoutError, builtin_layout_names, load_layout, parse_layout, random_maze
from .render import render_maze

__all__ = [
    "AGENTS",
    "DEFAULTS",
    "DEFAULT_LAYOUT",
    "DEFAULT_SPEED",
    "AgentGeometry",
    "GoalMazeEnv",
    "Layout",
    "LayoutError",
    "Obstacles",
    "PointMass",
    "VisibilityGraph",
    "builtin_layout_names",
    "load_layout",
    "merge_cells",
    "parse_layout",
    "random_maze",
    "render_maze",
    "shortest_path_lengths",
]
