"""Figures of one agent phase's finished sub-tasks, logged every iteration under `copilot/diag/...` by
every agent-based algorithm (SAC's sub-task is the whole task; CO-PILOT's a planned segment):

    success_after_reached / success_after_failed
                                    sub-task success of the 2nd, 3rd, ... sub-task of a layer, split by
                                    whether the sub-task before it in the same layer was reached: a
                                    large gap is the cascade of failures the paper's "continue from
                                    where the agent stopped" produces
    first_subtask_trivial           share of first sub-tasks of a layer whose sub-goal already lies
                                    within the success radius of s0 (reached in one step: says little)
    subtask_collided                share of sub-tasks that ended against an obstacle
    dtau_tuple_length_mean/_max     length of the sub-tasks (start -> where it ended): CO-PILOT's D_tau
                                    tuples

Pure numpy on the `subtask_records` columns, so tested on hand-made records.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from copilot_ray import keys

ArrayFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def traversal_diagnostics(
    records: dict[str, np.ndarray], *, distance: ArrayFn, success_radius: float
) -> dict[str, float]:
    """Figures of one agent phase's finished sub-tasks (the `subtask_records` columns; `goal`, the
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
