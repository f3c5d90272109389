"""What the maze's extended bodies (the rigid stick, the snake) share: exact clearance of segments, and
motion checks by conservative advancement that never miss a wall.

A body made of segments knows its exact clearance (distance to the nearest obstacle or the border) at
any configuration. A straight motion in configuration space (wrapped angles the short way round) is
then checked by conservative advancement: at clearance d the motion moves on by the fraction of it
over which no body point moves more than d, so every skipped interval is certified free and no wall,
however thin, is jumped. The motion is free when this reaches its end; it collides when the clearance
falls to `CONTACT` (a touching contact: obstacles are closed, as for the point mass).

How fast a body point can move is read off the distance weights: for every dimension after the
position, its weight is the farthest a body point lies from the joint it turns (a stick's half length,
a snake joint's reach), so |d position| + sum_i w_i |d_i| bounds any point's travel over a motion, and
the distance sqrt(sum_i (w_i d_i)^2) counts a turn as far as the body's tip moves.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import TYPE_CHECKING

import numpy as np

from .agents import AgentGeometry

if TYPE_CHECKING:
    from .geometry import Obstacles

CONTACT = 1e-7  # clearance at which a motion counts as touching (colliding)
MAX_ADVANCES = 10_000  # per motion; a motion still undecided then is reported colliding
COLLISION_SAMPLES = 32  # configurations per motion in `motion_collision_lengths`


def wrap_angle(theta: np.ndarray) -> np.ndarray:
    """Angles in [-pi, pi)."""
    return (np.asarray(theta, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[..., 2] points to segments a -> b ([..., 2], broadcast) -> distances [...]."""
    d = b - a
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * d), axis=-1)


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
        ends = np.minimum(obstacles.box_distances(a), obstacles.box_distances(b))  # [N, B]
        corners = np.stack(
            [lo, np.stack([lo[:, 0], hi[:, 1]], 1), hi, np.stack([hi[:, 0], lo[:, 1]], 1)], axis=1
        )  # [B, 4, 2]
        to_corners = _point_segment_distance(corners[None], a[:, None, None], b[:, None, None]).min(axis=2)
        out = np.minimum(out, np.minimum(ends, to_corners).min(axis=1))
    out[obstacles.segments_collide(a, b)] = 0.0
    return out


def advance_motions(clearance, along, a: np.ndarray, b: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """bool [N]: do the motions a -> b collide? Conservative advancement (module docstring).

    clearance(configs): the body's exact clearance; along(a, b, t): the configurations a fraction t of
    the way; speed [N]: how far any body point moves per unit of t at most.
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


class ExtendedBody(AgentGeometry):
    """An agent made of segments, with its position in dims 0, 1 (see the module docstring).

    Subclasses give `clearance` (exact), `distance_weights` (1, 1, then each further dim's reach) and
    `angle_dims`; distance, interpolation and both motion checks follow from them.
    """

    @property
    @abstractmethod
    def distance_weights(self) -> tuple[float, ...]: ...

    def _delta(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """b - a with the wrapped angles the short way round."""
        d = np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)
        for i in self.angle_dims:
            d[..., i] = wrap_angle(d[..., i])
        return d

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.sqrt(((np.asarray(self.distance_weights) * self._delta(a, b)) ** 2).sum(-1))

    def interpolate(self, a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Configurations [N, d] a fraction t [N] of the way from a to b (angles the short way round)."""
        c = a + t[:, None] * self._delta(a, b)
        for i in self.angle_dims:
            c[:, i] = wrap_angle(c[:, i])
        return c

    def _motions(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        shape = (-1, self.config_dim)
        return np.asarray(a, dtype=np.float64).reshape(shape), np.asarray(b, dtype=np.float64).reshape(shape)

    def motions_collide(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N], by conservative advancement: never reports a colliding motion free."""
        a, b = self._motions(a, b)
        d = self._delta(a, b)
        weights = np.asarray(self.distance_weights[2:])
        speed = np.hypot(d[:, 0], d[:, 1]) + (weights * np.abs(d[:, 2:])).sum(axis=1)
        return advance_motions(lambda c: self.clearance(obstacles, c), self.interpolate, a, b, speed)

    def motion_collision_lengths(self, obstacles: Obstacles, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """float [N]: the motion's length times the share of `COLLISION_SAMPLES` evenly spaced
        configurations along it that collide (an estimate, for the planner's `collision_cost: length`)."""
        a, b = self._motions(a, b)
        hits = np.stack(
            [
                self.clearance(obstacles, self.interpolate(a, b, np.full(len(a), t))) <= CONTACT
                for t in np.linspace(0.0, 1.0, COLLISION_SAMPLES)
            ],
            axis=1,
        )
        return self.distance(a, b) * hits.mean(axis=1)
