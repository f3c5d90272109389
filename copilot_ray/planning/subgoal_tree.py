"""Batched sub-goal trees (paper Sec. 3.3, Eq. 7).

A tree of depth ``K`` over a batch of ``B`` tasks is one array of shape ``[B, 2^K + 1, d]``: index 0 is the
start ``s0``, index ``2^K`` the goal ``g``, and layer ``k`` (0 <= k <= K) is the path through the indices
``j * 2^(K-k)`` for ``j = 0..2^k``. Layer ``k`` adds the midpoints at odd ``j``; each midpoint at index
``m`` splits the segment between its parents ``m - 2^(K-k)`` and ``m + 2^(K-k)``, both of which belong to
layer ``k - 1``. Entries of layers not yet sampled are NaN.

Everything here is index arithmetic on numpy arrays; it works for numpy and torch arrays alike where
fancy indexing along axis 1 is supported.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = [
    "SubgoalTree",
    "check_depth",
    "check_layer",
    "depth_of",
    "empty_tree",
    "layer_indices",
    "layer_path",
    "layer_segments",
    "new_layer_indices",
    "path_indices",
    "parent_indices",
    "tree_size",
]


def check_depth(K: int) -> int:
    """Return ``K`` as an int, raising ``ValueError`` unless it is an integer >= 1."""
    if isinstance(K, bool) or not isinstance(K, int | np.integer) or int(K) < 1:
        raise ValueError(f"tree depth K must be an integer >= 1, got K={K!r}")
    return int(K)


def check_layer(K: int, k: int, *, allow_zero: bool = True) -> int:
    K = check_depth(K)
    lo = 0 if allow_zero else 1
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or not lo <= int(k) <= K:
        raise ValueError(f"layer k must be an integer in [{lo}, {K}] for tree depth K={K}, got k={k!r}")
    return int(k)


def tree_size(K: int) -> int:
    """Number of nodes of a depth-K tree: 2^K + 1 (start, 2^K - 1 sub-goals, goal)."""
    return 2 ** check_depth(K) + 1


@lru_cache(maxsize=256)
def _layer_indices(K: int, k: int) -> np.ndarray:
    out = np.arange(2**k + 1, dtype=np.int64) * 2 ** (K - k)
    out.setflags(write=False)
    return out


def layer_indices(K: int, k: int) -> np.ndarray:
    """Indices of layer k's path in a depth-K tree: ``j * 2^(K-k)``, j = 0..2^k (read-only array)."""
    return _layer_indices(check_depth(K), check_layer(K, k))


@lru_cache(maxsize=256)
def _new_layer_indices(K: int, k: int) -> np.ndarray:
    out = (2 * np.arange(2 ** (k - 1), dtype=np.int64) + 1) * 2 ** (K - k)
    out.setflags(write=False)
    return out


def new_layer_indices(K: int, k: int) -> np.ndarray:
    """Indices of the 2^(k-1) midpoints that layer k (>= 1) adds: odd ``j * 2^(K-k)``."""
    return _new_layer_indices(check_depth(K), check_layer(K, k, allow_zero=False))


def parent_indices(K: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Left and right parent indices (both in layer k-1) of each midpoint added by layer k."""
    mid = new_layer_indices(K, k)
    half = 2 ** (K - k)
    return mid - half, mid + half


def depth_of(trees) -> int:
    """Depth K of trees shaped ``[..., 2^K + 1, d]``; ValueError if the node count is not 2^K + 1."""
    n = int(trees.shape[-2]) - 1
    if n < 2 or n & (n - 1):
        raise ValueError(
            f"trees must have 2^K + 1 nodes (K >= 1) along axis -2, got shape {tuple(trees.shape)}"
        )
    return n.bit_length() - 1


def empty_tree(starts, goals, K: int, dtype=np.float32) -> np.ndarray:
    """A ``[B, 2^K + 1, d]`` tree with start and goal set and every sub-goal NaN."""
    K = check_depth(K)
    starts = np.asarray(starts, dtype=dtype)
    goals = np.asarray(goals, dtype=dtype)
    if starts.ndim != 2 or starts.shape != goals.shape:
        raise ValueError(
            f"starts and goals must both have shape [B, d], got {starts.shape} and {goals.shape}"
        )
    B, d = starts.shape
    trees = np.full((B, 2**K + 1, d), np.nan, dtype=dtype)
    trees[:, 0] = starts
    trees[:, -1] = goals
    return trees


def layer_path(trees, K: int, k: int):
    """Layer k's path ``[B, 2^k + 1, d]`` of depth-K trees ``[B, 2^K + 1, d]``."""
    return trees[:, layer_indices(K, k)]


def layer_segments(trees, K: int, k: int):
    """Layer k's 2^k segments flattened for batched cost evaluation.

    Returns ``(a, b)``, each ``[B * 2^k, d]``, row ``i * 2^k + t`` being segment t of tree i.
    """
    path = layer_path(trees, K, k)
    d = path.shape[-1]
    a = path[:, :-1].reshape(-1, d)
    b = path[:, 1:].reshape(-1, d)
    return a, b


@dataclass(frozen=True)
class SubgoalTree:
    """The index layout of a depth-K sub-goal tree, as an object (thin wrapper over the functions)."""

    depth: int

    def __post_init__(self) -> None:
        check_depth(self.depth)

    @property
    def size(self) -> int:
        return tree_size(self.depth)

    @property
    def horizon(self) -> int:
        """T = 2^K, the number of segments of the finest layer."""
        return 2**self.depth

    def layer_indices(self, k: int) -> np.ndarray:
        return layer_indices(self.depth, k)

    def new_layer_indices(self, k: int) -> np.ndarray:
        return new_layer_indices(self.depth, k)

    def parent_indices(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        return parent_indices(self.depth, k)

    def empty(self, starts, goals, dtype=np.float32) -> np.ndarray:
        return empty_tree(starts, goals, self.depth, dtype=dtype)

    def layer_path(self, trees, k: int):
        return layer_path(trees, self.depth, k)

    def layer_segments(self, trees, k: int):
        return layer_segments(trees, self.depth, k)


def path_indices(depth: int, k: int) -> np.ndarray:
    """Indices of layer k's path in a tree; depth 0 (no planner: the tree is [s0, g]) has only layer 0."""
    return np.array([0, 1]) if depth == 0 else layer_indices(depth, k)
