"""Environment ids -> factories. A new environment adds one line to ENV_FACTORIES.

Factories are "module:function" strings, imported on first use, so asking for the maze never imports
MuJoCo or Box2D.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import gymnasium as gym

ENV_FACTORIES: dict[str, str] = {
    "maze-point": "copilot_ray.envs.maze.env:make_maze_point",
    "maze-rigid": "copilot_ray.envs.maze.env:make_maze_rigid",
    "maze-snake": "copilot_ray.envs.maze.env:make_maze_snake",
    "ant-maze": "copilot_ray.envs.ant_maze:make_ant_maze",
    "walker-stumps": "copilot_ray.envs.stump_tracks:make_walker_stumps",
    "walker-stumps-short": "copilot_ray.envs.stump_tracks:make_walker_stumps_short",
    "walker-stumps-long": "copilot_ray.envs.stump_tracks:make_walker_stumps_long",
}


class UnknownEnvError(ValueError):
    """An env id that is not registered."""


def env_ids() -> list[str]:
    return sorted(ENV_FACTORIES)


def factory(env_id: str) -> Callable[..., gym.Env]:
    if env_id not in ENV_FACTORIES:
        raise UnknownEnvError(f"unknown env id {env_id!r}; known ids: {', '.join(env_ids())}")
    module, name = ENV_FACTORIES[env_id].split(":")
    return getattr(importlib.import_module(module), name)


def make(env_id: str, **env_config: Any) -> gym.Env:
    """Build env `env_id`; unknown env_config keys raise a ValueError listing the valid ones."""
    return factory(env_id)(**env_config)


def register_with_ray() -> None:
    """Register every id with Ray Tune, so `config.environment("maze-point", env_config=...)` works."""
    from ray.tune.registry import register_env  # ray is slow to import: only here

    for env_id in ENV_FACTORIES:
        # Bind env_id now; a plain closure would see the loop's last id. RLlib's EnvContext is a dict.
        register_env(env_id, lambda cfg, _id=env_id: make(_id, **dict(cfg or {})))
