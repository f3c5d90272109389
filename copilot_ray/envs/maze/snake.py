"""A 3-link snake in the maze: configuration (x, y, theta1, theta2, theta3); the paper's 5-D maze agent.

What the paper leaves open (its Appendix B is not available) and what is chosen here:

* The body is a chain of three segments of `LINK` = 0.02 each (0.06 in all, shorter than the narrowest
  corridor of every built-in layout). (x, y) is the base, the free end of link 1; theta1 is link 1's
  heading (wrapped to [-pi, pi)); theta2 and theta3 are the joints' bends relative to the link before,
  limited to [-JOINT_LIMIT, JOINT_LIMIT] (2 pi / 3) so the chain cannot fold onto itself. The links do
  not collide with each other (the limits keep them apart); they collide with walls and the border.
* One step: the base moves by `speed * a[:2] / max(1, |a[:2]|)` and joint j by `a[2 + j] * speed /
  REACH[j]`, where REACH[j] is the chain's length beyond joint j, so each of the four contributions
  moves no body point more than `speed`.
* Distance: sqrt(dx^2 + dy^2 + sum_j (REACH[j] * dtheta_j)^2), theta1 wrapped: a joint's turn counts as
  far as the chain's tip moves because of it. A full-speed step is 2 x speed.
* Motion collision never misses: conservative advancement (`bodies.py`) on the chain's exact clearance
  (the smallest of its links'), with every body point moving at most |dp| + sum_j REACH[j] |dtheta_j|
  over a motion.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .bodies import ExtendedBody, segment_clearance, wrap_angle

if TYPE_CHECKING:
    from .geometry import Obstacles
    from .render import Canvas

LINK = 0.02
LINKS = 3
JOINT_LIMIT = 2 * np.pi / 3
REACH = np.array([3 * LINK, 2 * LINK, LINK])  # chain length beyond joint j (base turn, joint 2, joint 3)


def joints(configs: np.ndarray) -> np.ndarray:
    """[N, 4, 2]: the base, the two inner joints and the tip of the chain at each configuration."""
    c = np.asarray(configs, dtype=np.float64).reshape(-1, 5)
    heading = np.cumsum(c[:, 2:5], axis=1)  # absolute angle of each link
    steps = LINK * np.stack([np.cos(heading), np.sin(heading)], axis=2)  # [N, 3, 2]
    return np.concatenate([c[:, None, :2], c[:, None, :2] + np.cumsum(steps, axis=1)], axis=1)


class Snake(ExtendedBody):
    """The chain described in the module docstring; configuration (x, y, theta1, theta2, theta3)."""

    name = "snake"
    body = f"a chain of {LINKS} links of length {LINK:g}"
    config_dim = 5
    action_dim = 5
    angle_dims = (2,)

    def __init__(self, speed: float):
        self.speed = self._checked_speed(speed)
        self.turn_rates = self.speed / REACH  # radians per step at a[2 + j] = 1

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.array([0.0, 0.0, -np.pi, -JOINT_LIMIT, -JOINT_LIMIT]),
            np.array([1.0, 1.0, np.pi, JOINT_LIMIT, JOINT_LIMIT]),
        )

    @property
    def nominal_step_distance(self) -> float:
        return 2.0 * self.speed

    @property
    def distance_weights(self) -> tuple[float, ...]:
        return (1.0, 1.0, *map(float, REACH))

    def step(self, config: np.ndarray, action: np.ndarray) -> np.ndarray:
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        c = np.asarray(config, dtype=np.float64).copy()
        c[:2] += self.speed * a[:2] / max(1.0, float(np.linalg.norm(a[:2])))
        c[2:] += self.turn_rates * a[2:]
        c[2] = wrap_angle(c[2])
        c[3:] = np.clip(c[3:], -JOINT_LIMIT, JOINT_LIMIT)
        return c

    def clearance(self, obstacles: Obstacles, configs: np.ndarray) -> np.ndarray:
        pts = joints(configs)
        n = len(pts)
        per_link = segment_clearance(obstacles, pts[:, :-1].reshape(-1, 2), pts[:, 1:].reshape(-1, 2))
        out = per_link.reshape(n, LINKS).min(axis=1)
        # A configuration beyond the joint limits is not one the snake can take.
        c = np.asarray(configs, dtype=np.float64).reshape(-1, 5)
        out[(np.abs(c[:, 3:]) > JOINT_LIMIT + 1e-12).any(axis=1)] = 0.0
        return out

    def draw(self, canvas: Canvas, config: np.ndarray, color: tuple[int, int, int]) -> None:
        pts = joints(config)[0]
        for p, q in zip(pts[:-1], pts[1:], strict=True):
            canvas.segment(p, q, width_px=max(2.0, canvas.size / 100), color=color)
