"""Agent geometries: what moves through the maze, in its configuration space.

The maze env only talks to an `AgentGeometry`, so a rigid body (`rigid_body.py`: x, y, angle) or a
3-link snake (base + joint angles) plugs in with one line in `env.AGENTS`. The goal
is a full configuration, so planning happens in configuration space.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .geometry import Obstacles
    from .render import Canvas


class AgentGeometry(ABC):
    """Kinematics and collision geometry of one agent kind."""

    name: str
    body: str  # what collides, in words (error messages)
    config_dim: int
    action_dim: int
    # Wrapped angles among the configuration's dims, and each dim's weight in `distance`
    # (distance = sqrt(sum_i (w_i * d_i)^2), angles wrapped): what a planner over the same space needs.
    angle_dims: tuple[int, ...] = ()

    @property
    def distance_weights(self) -> tuple[float, ...]:
        return (1.0,) * self.config_dim

    @staticmethod
    def _checked_speed(speed: float) -> float:
        """`speed` as a float; a ValueError naming it unless it is a positive finite number."""
        if not (np.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a positive number, got {speed!r}")
        return float(speed)

    @property
    @abstractmethod
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of the configuration space, float64 [config_dim] each."""

    @property
    @abstractmethod
    def nominal_step_distance(self) -> float:
        """Furthest the configuration moves (in `distance` units) in one step."""

    @abstractmethod
    def step(self, config: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The configuration the action would reach if nothing were in the way."""

    def step_batch(self, configs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """`step` of N configurations at once: [N, d], [N, a] -> [N, d] (evaluation's lockstep rollouts)."""
        return np.stack([self.step(c, a) for c, a in zip(configs, actions, strict=True)])

    @abstractmethod
    def motions_collide(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N]: does moving straight (in configuration space) from a[i] to b[i] hit anything?"""

    @abstractmethod
    def motion_collision_lengths(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """float [N]: length of the straight motion a[i] -> b[i] spent in collision (planning costs)."""

    @abstractmethod
    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """float [N]: distance between configurations (wraps angles where there are any)."""

    @abstractmethod
    def clearance(self, obstacles: Obstacles, configs: np.ndarray) -> np.ndarray:
        """float [N]: distance from the agent's body at each configuration to obstacles and border."""

    @abstractmethod
    def draw(self, canvas: Canvas, config: np.ndarray, color: tuple[int, int, int]) -> None:
        """Draw the agent's body at `config`."""

    def shortest_path_lengths(
        self, obstacles: Obstacles, starts: np.ndarray, goals: np.ndarray
    ) -> np.ndarray:
        """float [N]: exact shortest collision-free path lengths; only where an exact method exists."""
        raise NotImplementedError(f"no exact shortest path for agent {self.name!r}")


class PointMass(AgentGeometry):
    """A point at (x, y) that moves by `speed * a / max(1, |a|)` per step, a in [-1, 1]^2.

    The action is clipped to the unit disc (not the box) so that no direction is faster than `speed`
    and `nominal_step_distance` is exactly `speed`.
    """

    name = "point"
    body = "a point"
    config_dim = 2
    action_dim = 2

    def __init__(self, speed: float, bounds: tuple[np.ndarray, np.ndarray] | None = None):
        self.speed = self._checked_speed(speed)
        # The unit square of the 1 x 1 mazes unless a larger plane is given (the Ant maze's, in metres).
        low, high = bounds if bounds is not None else (np.zeros(2), np.ones(2))
        self._bounds = (np.asarray(low, np.float64).copy(), np.asarray(high, np.float64).copy())

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._bounds[0].copy(), self._bounds[1].copy()

    @property
    def nominal_step_distance(self) -> float:
        return self.speed

    def step(self, config: np.ndarray, action: np.ndarray) -> np.ndarray:
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        norm = float(np.linalg.norm(action))
        return np.asarray(config, dtype=np.float64) + self.speed * action / max(1.0, norm)

    def step_batch(self, configs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        actions = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        norms = np.sqrt(actions[:, 0] * actions[:, 0] + actions[:, 1] * actions[:, 1])
        return np.asarray(configs, dtype=np.float64) + self.speed * actions / np.maximum(1.0, norms)[:, None]

    def motions_collide(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return obstacles.segments_collide(a, b)

    def motion_collision_lengths(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return obstacles.collision_lengths(a, b)

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64), axis=-1)

    def clearance(self, obstacles: Obstacles, configs: np.ndarray) -> np.ndarray:
        return obstacles.clearance(configs)

    def draw(self, canvas: Canvas, config: np.ndarray, color: tuple[int, int, int]) -> None:
        canvas.disc(np.asarray(config)[:2], radius_px=max(2.0, canvas.size / 80), color=color)

    def shortest_path_lengths(
        self, obstacles: Obstacles, starts: np.ndarray, goals: np.ndarray
    ) -> np.ndarray:
        return obstacles.visibility_graph.lengths(starts, goals)
