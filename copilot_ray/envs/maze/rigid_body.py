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
* Motion collision never misses: a straight motion in configuration space (theta along the shorter
  way round) is advanced by conservative advancement: at configuration c the body's clearance d (its
  exact distance to the nearest obstacle or the border) is computed, and the motion moves on by the
  fraction of it over which no body point moves more than d (a point moves at most |dp| + LENGTH / 2 *
  |dtheta| per unit of the motion). A motion is reported free only when this reaches its end; it is
  reported colliding when the clearance falls below `CONTACT` (1e-7), which is what a touching contact
  looks like (closed obstacles: touching collides, as for the point mass). No check can miss a wall,
  however thin: every interval the motion skips is certified free by the clearance.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .agents import AgentGeometry

if TYPE_CHECKING:
    from .geometry import Obstacles
    from .render import Canvas

LENGTH = 0.05
CONTACT = 1e-7  # clearance at which a motion counts as touching (colliding)
MAX_ADVANCES = 10_000  # per motion; a motion still undecided then is reported colliding


def wrap_angle(theta: np.ndarray) -> np.ndarray:
    """Angles in [-pi, pi)."""
    return (np.asarray(theta, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def stick_endpoints(configs: np.ndarray, length: float = LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """The two ends [N, 2] of the stick at each configuration (x, y, theta)."""
    c = np.asarray(configs, dtype=np.float64).reshape(-1, 3)
    half = 0.5 * length * np.stack([np.cos(c[:, 2]), np.sin(c[:, 2])], axis=1)
    return c[:, :2] - half, c[:, :2] + half


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[..., 2] points to segments a -> b ([..., 2], broadcast) -> distances [...]."""
    d = b - a
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * d), axis=-1)


def _point_box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """[N, 2] points to boxes [B, 2] -> [N, B] (0 inside)."""
    gap = np.maximum(np.maximum(lo[None] - p[:, None], p[:, None] - hi[None]), 0.0)
    return np.sqrt((gap**2).sum(axis=2))


def segment_clearance(obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """float [N]: exact distance from each closed segment a -> b to the obstacles and the border; 0 when
    it touches or crosses one (or leaves the unit square).

    Two disjoint convex shapes are closest at a vertex of one of them: the segment's ends against each
    box, and each box's corners against the segment. The square is convex, so the distance to its
    border is the smaller of the two ends' distances.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    border = np.minimum(np.minimum(a, 1.0 - a).min(axis=1), np.minimum(b, 1.0 - b).min(axis=1))
    out = np.clip(border, 0.0, None)
    if len(obstacles.lo):
        lo, hi = obstacles.lo, obstacles.hi
        ends = np.minimum(_point_box_distance(a, lo, hi), _point_box_distance(b, lo, hi))  # [N, B]
        corners = np.stack(
            [lo, np.stack([lo[:, 0], hi[:, 1]], 1), hi, np.stack([hi[:, 0], lo[:, 1]], 1)], axis=1
        )  # [B, 4, 2]
        to_corners = _point_segment_distance(corners[None], a[:, None, None], b[:, None, None]).min(axis=2)
        out = np.minimum(out, np.minimum(ends, to_corners).min(axis=1))
    out[obstacles.segments_collide(a, b)] = 0.0
    return out


class RigidBody(AgentGeometry):
    """The stick described in the module docstring; configuration (x, y, theta)."""

    name = "rigid"
    config_dim = 3
    action_dim = 3
    angle_dims = (2,)

    def __init__(self, speed: float, length: float = LENGTH):
        if not (np.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a positive number, got {speed!r}")
        if not (np.isfinite(length) and 0 < length < 0.5):
            raise ValueError(f"length must be in (0, 0.5), got {length!r}")
        self.speed = float(speed)
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

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64)
        d = b - a
        turn = 0.5 * self.length * wrap_angle(d[..., 2])
        return np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + turn**2)

    def clearance(self, obstacles: Obstacles, configs: np.ndarray) -> np.ndarray:
        return segment_clearance(obstacles, *stick_endpoints(configs, self.length))

    def _along(self, a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Configurations a fraction t [N] of the way from a to b (theta the shorter way round)."""
        d = b - a
        d[:, 2] = wrap_angle(d[:, 2])
        c = a + t[:, None] * d
        c[:, 2] = wrap_angle(c[:, 2])
        return c

    def motions_collide(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N], by conservative advancement (module docstring): never reports a colliding motion free."""
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        d = b - a
        # Fastest any body point moves per unit of the motion's parameter t.
        speed = np.hypot(d[:, 0], d[:, 1]) + 0.5 * self.length * np.abs(wrap_angle(d[:, 2]))
        return advance_motions(lambda c: self.clearance(obstacles, c), self._along, a, b, speed)

    def motion_collision_lengths(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """float [N]: the motion's length times the share of 32 evenly spaced configurations along it that
        collide (an estimate, for the planner's `collision_cost: length`)."""
        a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
        ts = np.linspace(0.0, 1.0, 32)
        hits = np.stack(
            [self.clearance(obstacles, self._along(a, b, np.full(len(a), t))) <= CONTACT for t in ts], axis=1
        )
        return self.distance(a, b) * hits.mean(axis=1)

    def draw(self, canvas: Canvas, config: np.ndarray, color: tuple[int, int, int]) -> None:
        p, q = stick_endpoints(config, self.length)
        canvas.segment(p[0], q[0], width_px=max(2.0, canvas.size / 100), color=color)


def advance_motions(clearance, along, a: np.ndarray, b: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """bool [N]: do the motions a -> b collide? Conservative advancement, shared by the maze's bodies.

    clearance(configs) is the body's exact distance to obstacles and border; along(a, b, t) the
    configurations a fraction t of the way; speed [N] bounds how far any body point moves per unit of t.
    At clearance d the motion moves on by d / speed (no point can reach an obstacle in between); it
    collides when the clearance falls to `CONTACT` and is free when it reaches b.
    """
    if a.shape != b.shape:
        raise ValueError(f"motion endpoints differ in shape: {a.shape} vs {b.shape}")
    t = np.zeros(len(a))
    collide = np.zeros(len(a), dtype=bool)
    active = np.ones(len(a), dtype=bool)
    for _ in range(MAX_ADVANCES):
        idx = np.flatnonzero(active)
        if not len(idx):
            break
        gap = clearance(along(a[idx], b[idx], t[idx]))
        hit = gap <= CONTACT
        collide[idx[hit]] = True
        t[idx] = t[idx] + np.where(speed[idx] > 0, gap / np.maximum(speed[idx], 1e-300), np.inf)
        done = hit | (t[idx] >= 1.0)
        if (~hit & done).any():  # the last stretch reached b: check b itself (closed obstacles)
            end = idx[~hit & done]
            collide[end] = clearance(b[end]) <= CONTACT
        active[idx[done]] = False
    collide[active] = True  # undecided after MAX_ADVANCES: grazing a wall, count it as touching
    return collide
