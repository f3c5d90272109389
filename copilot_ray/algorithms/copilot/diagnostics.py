"""Why a CO-PILOT run does (not) learn: figures logged every iteration under `copilot/diag/...`.

Plans (the trees the agent is about to traverse), per layer k >= 1:

    subgoal_in_obstacle_layer_<k>   share of layer k's new sub-goals inside an obstacle (unreachable)
    segment_length_layer_<k>        mean length of layer k's segments
    reachable_length_layer_<k>      the longest segment one sub-task can cover: step limit x nominal
                                    step distance + success radius
    segment_unreachable_layer_<k>   share of layer k's segments longer than that

Traversals (the finished sub-tasks of one agent phase):

    success_after_reached / success_after_failed
                                    sub-task success of the 2nd, 3rd, ... sub-task of a layer, split by
                                    whether the sub-task before it in the same layer was reached: a
                                    large gap is the cascade of failures the paper's "continue from
                                    where the agent stopped" produces
    first_subtask_trivial           share of first sub-tasks of a layer whose sub-goal already lies
                                    within the success radius of s0 (reached in one step: says little)
    subtask_collided                share of sub-tasks that ended against an obstacle
    dtau_tuple_length_mean/_max     length of the measured D_tau tuples (start -> where it ended)

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


def traversal_diagnostics(
    records: dict[str, np.ndarray], *, distance: ArrayFn, success_radius: float
) -> dict[str, float]:
    """Figures of one agent phase's finished sub-tasks (the `_subtask_records` columns; `goal`, the
    sub-goals, is optional and needed for `first_subtask_trivial`)."""
    task, layer, index = records["task"], records["layer"], records["index"]
    reached = records["reached"].astype(bool)
    # Traversal order: task by task, layers K..0, sub-goals left to right.
    order = np.lexsort((index, -layer, task))
    task, layer, index, reached = task[order], layer[order], index[order], reached[order]
    same_run = (task[1:] == task[:-1]) & (layer[1:] == layer[:-1]) & (index[1:] == index[:-1] + 1)
    prev_reached, this_reached = reached[:-1][same_run], reached[1:][same_run]
    out: dict[str, float] = {}
    if (prev_reached).any():
        out[keys.DIAG_SUCCESS_AFTER_REACHED] = float(this_reached[prev_reached].mean())
    if (~prev_reached).any():
        out[keys.DIAG_SUCCESS_AFTER_FAILED] = float(this_reached[~prev_reached].mean())
    if "goal" in records:
        first = records["index"] == 1
        if first.any():
            near = distance(records["start"][first], records["goal"][first]) <= success_radius
            out[keys.DIAG_FIRST_SUBTASK_TRIVIAL] = float(np.mean(near))
    if "collided" in records:
        out[keys.DIAG_SUBTASK_COLLIDED] = float(np.mean(records["collided"]))
    lengths = distance(records["start"], records["end"])
    out[keys.DIAG_DTAU_TUPLE_LENGTH_MEAN] = float(np.mean(lengths))
    out[keys.DIAG_DTAU_TUPLE_LENGTH_MAX] = float(np.max(lengths))
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
