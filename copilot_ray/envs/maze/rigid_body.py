"""A rigid body in the maze: a stick (thin segment) at (x, y) turned by theta; the paper's 3-D maze agent.

What the paper leaves open (its Appendix B, with the bodies' shapes and sizes, is not available) and
what is chosen here:

* The body is a segment of length `LENGTH` = 0.05 centred on (x, y), at angle theta (radians, wrapped
  to [-pi, pi)). It is shorter than the narrowest corridor of every built-in layout (one cell: 1/11 =
  0.091 on four-rooms and spiral, 1/8 on the others), so it can turn anywhere it has room to stand
  and the free configurations of a layout are connected whenever its free cells are.
* One step: the centre moves by `speed * a[:2] / max(1, |a[:2]|)` and theta by
  `a[2] * speed / (LENGTH / 2)`, a in [-1, 1]^3, so no point of the body moves more than 2 x speed.
* Distance between configurations (the planner's Euclidean term and the success test):
  sqrt(dx^2 + dy^2 + (LENGTH / 2 * dtheta)^2) with dtheta wrapped: a turn counts as far as the stick's
  end moves. A full-speed step (translation and turn together) is sqrt(2) x speed.
* Motion collision never misses: conservative advancement on the stick's exact clearance
  (`bodies.py`); a point of the stick moves at most |dp| + LENGTH / 2 * |dtheta| over a motion.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .bodies import ExtendedBody, segment_clearance, wrap_angle

if TYPE_CHECKING:
    from .geometry import Obstacles
    from .render import Canvas

LENGTH = 0.05


def stick_endpoints(configs: np.ndarray, length: float = LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """The two ends [N, 2] of the stick at each configuration (x, y, theta)."""
    c = np.asarray(configs, dtype=np.float64).reshape(-1, 3)
    half = 0.5 * length * np.stack([np.cos(c[:, 2]), np.sin(c[:, 2])], axis=1)
    return c[:, :2] - half, c[:, :2] + half


class RigidBody(ExtendedBody):
    """The stick described in the module docstring; configuration (x, y, theta)."""

    name = "rigid"
    body = f"a stick of length {LENGTH:g}"
    config_dim = 3
    action_dim = 3
    angle_dims = (2,)

    def __init__(self, speed: float, length: float = LENGTH):
        if not (np.isfinite(length) and 0 < length < 0.5):
            raise ValueError(f"length must be in (0, 0.5), got {length!r}")
        self.speed = self._checked_speed(speed)
        self.length = float(length)
        self.turn_rate = self.speed / (0.5 * self.length)  # radians per step at a[2] = 1

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([0.0, 0.0, -np.pi]), np.array([1.0, 1.0, np.pi])

    @property
    def nominal_step_distance(self) -> float:
        return float(np.sqrt(2.0) * self.speed)

    @property
    def distance_weights(self) -> tuple[float, ...]:
        return (1.0, 1.0, 0.5 * self.length)

    def step(self, config: np.ndarray, action: np.ndarray) -> np.ndarray:
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        c = np.asarray(config, dtype=np.float64)
        move = self.speed * a[:2] / max(1.0, float(np.linalg.norm(a[:2])))
        theta = wrap_angle(c[2] + self.turn_rate * a[2])
        return np.array([c[0] + move[0], c[1] + move[1], theta])

    def clearance(self, obstacles: Obstacles, configs: np.ndarray) -> np.ndarray:
        return segment_clearance(obstacles, *stick_endpoints(configs, self.length))

    def draw(self, canvas: Canvas, config: np.ndarray, color: tuple[int, int, int]) -> None:
        p, q = stick_endpoints(config, self.length)
        canvas.segment(p[0], q[0], width_px=max(2.0, canvas.size / 100), color=color)
