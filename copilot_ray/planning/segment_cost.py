"""Segment and tree costs for the planner (paper Eq. 8 and 11).

    c(a, b) = alpha * dist(a, b) + (1 - alpha) * tau_hat(a, b) + collision_penalty * [a-b collides]

``dist`` is the environment's ``goal_distance`` hook (Euclidean by default; it wraps angles where the goal
has angles). The collision term is the paper's additive penalty of 10 for a segment that trespasses an
obstacle (Sec. 4.1), ``collision_cost="indicator"``. ``collision_cost="length"`` charges
``collision_penalty * (length of a-b in collision + TOUCH_LENGTH * [a-b collides])`` instead: the length
term is SGT-PG's reference planner's (with 100), and is graded, where the indicator is flat inside an
obstacle (a planner whose samples all land in a thick wall gets no signal about which way is out).
The ``TOUCH_LENGTH`` (0.1) term keeps a segment that only touches an obstacle or the border, with zero
length in collision, from being free: without it the planner learned to park sub-goals on the border
(measured on four-rooms, K = 5: 0 % collision-free test plans). With the default penalty of 100 it is the
paper's 10 per colliding segment.

Units of the time cost. ``tau_hat`` is expressed in DISTANCE units, not in raw steps: a measured sub-task
of ``n`` steps is stored in D_tau as ``n * step_distance`` where ``step_distance`` is the environment's
nominal distance covered by one step (e.g. 0.05 per step for a point mass with maximal speed 0.05). Two
reasons: (1) the paper initialises D_tau with Euclidean distances as the "time" of 50,000 random pairs
(Sec. 4.1); those tuples and the measured ones must lie on one scale or the regression mixes two units;
(2) with that choice, alpha interpolates between two quantities of the same magnitude (a straight
free sub-task costs about its length under both terms), and the collision penalty of 10 means the same
thing (10 unit-box lengths) whatever alpha is. Converting steps to distance is done where tuples are
added (``TimeCostModel.add_steps``).

``tree_cost`` evaluates Eq. 8 restricted to layers 0..k (the J^k of Algorithm 1) for many trees with one
call to the segment cost over all their segments: no Python loop over trees or segments.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .subgoal_tree import check_layer, depth_of, layer_indices

__all__ = ["COLLISION_COSTS", "SegmentCost", "euclidean_distance", "tree_cost", "tree_segments"]

COLLISION_COSTS = ("indicator", "length")
TOUCH_LENGTH = 0.1  # with collision_cost="length": length charged for any colliding segment

ArrayFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def euclidean_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise Euclidean distance of ``[N, d]`` arrays -> ``[N]``."""
    return np.linalg.norm(np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64), axis=-1)


@dataclass
class SegmentCost:
    """Eq. 11 as a batched callable ``cost(a, b) -> [N]`` for ``a, b`` of shape ``[N, d]``.

    Attributes:
        alpha: weight of the distance term in [0, 1]; set it from the alpha schedule before each
            construction (it is a plain mutable attribute).
        time_cost: ``tau_hat(a, b) -> [N]`` in distance units (e.g. ``TimeCostModel.predict``); needed
            whenever alpha < 1.
        segments_collide: the environment's ``segments_collide(a, b) -> bool[N]``; None = no obstacles.
        distance: the environment's ``goal_distance(a, b) -> [N]``; None = Euclidean.
        collision_penalty: added per colliding segment (10 in the paper), or per unit of length in
            collision with ``collision_cost="length"``.
        collision_cost: "indicator" (the paper) or "length" (needs ``collision_lengths``).
        collision_lengths: the environment's ``collision_lengths(a, b) -> float[N]``.
    """

    alpha: float = 1.0
    time_cost: ArrayFn | None = None
    segments_collide: ArrayFn | None = None
    distance: ArrayFn | None = None
    collision_penalty: float = 10.0
    collision_cost: str = "indicator"
    collision_lengths: ArrayFn | None = None

    def __post_init__(self) -> None:
        self._check_alpha()
        if self.collision_cost not in COLLISION_COSTS:
            raise ValueError(
                f"collision_cost={self.collision_cost!r} is invalid: use one of {COLLISION_COSTS}"
            )
        if self.collision_cost == "length" and self.collision_lengths is None:
            raise ValueError("collision_cost='length' needs a collision_lengths(a, b) function")

    def _check_alpha(self) -> None:
        if not 0.0 <= float(self.alpha) <= 1.0:
            raise ValueError(f"alpha must lie in [0, 1], got alpha={self.alpha!r}")

    def components(self, a: np.ndarray, b: np.ndarray) -> dict[str, np.ndarray]:
        """The three terms separately: ``distance``, ``time`` (None if unused), ``collides`` (bool)."""
        a = np.asarray(a)
        b = np.asarray(b)
        dist = (self.distance or euclidean_distance)(a, b)
        tau = None
        if float(self.alpha) < 1.0:
            if self.time_cost is None:
                raise ValueError(f"alpha={self.alpha} < 1 needs a time_cost (tau_hat) function")
            tau = np.asarray(self.time_cost(a, b), dtype=np.float64)
        if self.segments_collide is None:
            collides = np.zeros(a.shape[0], dtype=bool)
        else:
            collides = np.asarray(self.segments_collide(a, b), dtype=bool)
        parts = {"distance": np.asarray(dist, dtype=np.float64), "time": tau, "collides": collides}
        if self.collision_cost == "length":
            parts["collision_length"] = np.asarray(self.collision_lengths(a, b), dtype=np.float64)
        return parts

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        self._check_alpha()
        parts = self.components(a, b)
        alpha = float(self.alpha)
        cost = alpha * parts["distance"]
        if parts["time"] is not None:
            cost = cost + (1.0 - alpha) * parts["time"]
        if self.collision_cost == "length":
            return cost + self.collision_penalty * (
                parts["collision_length"] + TOUCH_LENGTH * parts["collides"]
            )
        return cost + self.collision_penalty * parts["collides"]

    def tree_cost(self, trees: np.ndarray, K: int | None = None, upto_layer: int | None = None):
        """See :func:`tree_cost`."""
        return tree_cost(trees, K, upto_layer, self)


def tree_segments(trees: np.ndarray, K: int, upto_layer: int) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """All segments of layers 0..upto_layer of ``[N, 2^K + 1, d]`` trees, flattened.

    Returns ``(a, b, counts)`` with ``a, b`` of shape ``[N * (2^(k+1) - 1), d]``; per tree, layer 0's
    segment comes first, then layer 1's two, and so on (``counts[k] = 2^k``).
    """
    idx_a = np.concatenate([layer_indices(K, k)[:-1] for k in range(upto_layer + 1)])
    idx_b = np.concatenate([layer_indices(K, k)[1:] for k in range(upto_layer + 1)])
    d = trees.shape[-1]
    return (
        trees[:, idx_a].reshape(-1, d),
        trees[:, idx_b].reshape(-1, d),
        [2**k for k in range(upto_layer + 1)],
    )


def tree_cost(
    trees: np.ndarray, K: int | None, upto_layer: int | None, segment_cost: ArrayFn
) -> tuple[np.ndarray, np.ndarray]:
    """Per-layer path costs and their sum (Eq. 8 up to layer k = J^k of Algorithm 1).

    Args:
        trees: ``[N, 2^K + 1, d]``; layers 0..upto_layer must be filled.
        K: tree depth (None: read from the shape).
        upto_layer: last layer included (None: K).
        segment_cost: batched ``c(a, b) -> [M]``.
    Returns:
        ``(layer_costs [N, upto_layer + 1], total [N])`` where ``layer_costs[:, k]`` is the cost of layer
        k's path and ``total`` their sum.
    """
    trees = np.asarray(trees)
    K = depth_of(trees) if K is None else K
    k_max = K if upto_layer is None else check_layer(K, upto_layer)
    N = trees.shape[0]
    a, b, counts = tree_segments(trees, K, k_max)
    seg = np.asarray(segment_cost(a, b), dtype=np.float64).reshape(N, -1)
    ends = np.cumsum(counts)
    layer_costs = np.add.reduceat(seg, np.concatenate([[0], ends[:-1]]), axis=1)
    return layer_costs, layer_costs.sum(axis=1)
