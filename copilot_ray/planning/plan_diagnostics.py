"""Why a CO-PILOT run does (not) learn: figures logged every iteration under `copilot/diag/...`.

Plans (the trees the agent is about to traverse), per layer k >= 1:

    subgoal_in_obstacle_layer_<k>   share of layer k's new sub-goals inside an obstacle (unreachable)
    segment_length_layer_<k>        mean length of layer k's segments
    reachable_length_layer_<k>      the longest segment one sub-task can cover: step limit x nominal
                                    step distance + success radius
    segment_unreachable_layer_<k>   share of layer k's segments longer than that

The traversals' figures (of every agent, a planner or not) are copilot_ray.algorithms.sac.traversal_diagnostics.

The returned keys are the full metric names (`copilot_ray.keys.DIAG_*`). All functions are pure numpy on
arrays, so they are tested on hand-made trees.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from copilot_ray import keys
from copilot_ray.planning.subgoal_tree import new_layer_indices, path_indices

ArrayFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def plan_diagnostics(
    trees: np.ndarray,
    depth: int,
    *,
    point_collides: Callable[[np.ndarray], np.ndarray],
    distance: ArrayFn,
    reachable_length: Callable[[int], float],
) -> dict[str, float]:
    """Per-layer figures of `trees` [B, 2^K + 1, d] (see the module docstring).

    point_collides: [N, d] -> bool [N], True where a configuration is inside an obstacle.
    reachable_length: layer k -> the longest segment a layer-k sub-task can cover.
    """
    out: dict[str, float] = {}
    d = trees.shape[-1]
    for k in range(1, depth + 1):
        new = trees[:, new_layer_indices(depth, k)].reshape(-1, d)
        out[keys.DIAG_SUBGOAL_IN_OBSTACLE_LAYER + str(k)] = float(np.mean(point_collides(new)))
        path = trees[:, path_indices(depth, k)]
        lengths = distance(path[:, :-1].reshape(-1, d), path[:, 1:].reshape(-1, d))
        reach = float(reachable_length(k))
        out[keys.DIAG_SEGMENT_LENGTH_LAYER + str(k)] = float(np.mean(lengths))
        out[keys.DIAG_REACHABLE_LENGTH_LAYER + str(k)] = reach
        out[keys.DIAG_SEGMENT_UNREACHABLE_LAYER + str(k)] = float(np.mean(lengths > reach))
    return out


def tau_hat_profile(
    time_cost: ArrayFn,
    distance: ArrayFn,
    starts: np.ndarray,
    directions: np.ndarray,
    lengths: np.ndarray,
    low,
    high,
) -> tuple[np.ndarray, np.ndarray]:
    """tau_hat against segment length, for the report's diagnostics page.

    For each length in `lengths`: segments from `starts` along unit `directions` (ends clipped into the
    goal box [low, high]). Returns (mean distance, mean tau_hat), each [len(lengths)].
    """
    dist, tau = np.empty(len(lengths)), np.empty(len(lengths))
    for i, length in enumerate(lengths):
        ends = np.clip(starts + length * directions, low, high)
        dist[i] = float(np.mean(distance(starts, ends)))
        tau[i] = float(np.mean(time_cost(starts, ends)))
    return dist, tau
