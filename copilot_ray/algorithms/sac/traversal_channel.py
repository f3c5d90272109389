"""What the driver and its env runners' traversal envs exchange, typed once for both sides: the plan a
runner is given (`TraversalPlan`, sent with `load_plan`) and the record of every sub-task it finished
(`subtask_info` writes it into the episode's last info, `subtask_records` reads the episodes' back as
`Subtasks` columns), and what those columns say per tree layer (`traversal_stats`).

A runner's env is a gymnasium vector env around one `TraversalEnv` (RLlib's new stack has no typed
call into it): `load_plan` and `remaining` are the only places its methods are named.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np

from copilot_ray import keys

INFO_PREFIX = "subtask_"
IDLE_INFO = INFO_PREFIX + "idle"  # a placeholder episode before any plan: dropped by the driver


@dataclass(frozen=True)
class TraversalPlan:
    """The trees one runner traverses: `trees` [B, 2^K + 1, d] of tasks `task_ids` [B], depth K."""

    trees: np.ndarray
    depth: int
    task_ids: np.ndarray


def load_plan(runner, plan: TraversalPlan) -> int:
    """Gives `runner`'s traversal env its plan; the number of sub-tasks queued."""
    return runner.env.unwrapped.call("load_plan", plan.trees, plan.depth, plan.task_ids)[0]


def remaining(runner) -> int:
    """Sub-tasks of the plan `runner`'s traversal env has not started yet."""
    return runner.env.unwrapped.call("remaining")[0]


class Subtasks(TypedDict):
    """Columns of finished sub-tasks, one row each (goal-space points are float32 [N, d])."""

    start: np.ndarray  # where the sub-task began
    end: np.ndarray  # where the agent stopped
    goal: np.ndarray  # its sub-goal
    steps: np.ndarray  # int, the steps it took
    layer: np.ndarray  # int, its tree layer k
    index: np.ndarray  # int, its position in the layer (1..2^k)
    task: np.ndarray  # int, the training task's index
    reached: np.ndarray  # bool, the sub-goal reached
    collided: np.ndarray  # bool, ended against an obstacle without reaching it
    reset_to_state: np.ndarray  # bool, began with a reset to a missed sub-goal (a privilege)
    map_queries: np.ndarray  # int, questions to the map behind that reset (a privilege)


_DTYPES: dict[str, Any] = {
    "start": np.float32,
    "end": np.float32,
    "goal": np.float32,
    "steps": np.int64,
    "layer": np.int64,
    "index": np.int64,
    "task": np.int64,
    "reached": bool,
    "collided": bool,
    "reset_to_state": bool,
    "map_queries": np.int64,
}
assert set(_DTYPES) == set(Subtasks.__annotations__)


def subtask_info(*, idle: bool, **fields: Any) -> dict[str, Any]:
    """The info keys that record a finished sub-task (`fields`: every column of `Subtasks`)."""
    missing = set(_DTYPES) - set(fields)
    if missing or set(fields) - set(_DTYPES):
        raise ValueError(f"a sub-task record needs exactly {sorted(_DTYPES)}; missing {sorted(missing)}")
    return {IDLE_INFO: idle, **{INFO_PREFIX + name: value for name, value in fields.items()}}


def is_idle(info: dict[str, Any]) -> bool:
    return bool(info.get(IDLE_INFO, False))


def subtask_records(episodes) -> Subtasks:
    """The `Subtasks` of finished episodes (one sub-task each), read off each one's last info."""
    infos = [e.get_infos(-1) for e in episodes]
    return Subtasks(
        **{
            name: (np.stack if dtype is np.float32 else np.array)(
                [info[INFO_PREFIX + name] for info in infos]
            ).astype(dtype)
            for name, dtype in _DTYPES.items()
        }
    )


def concatenated(records: list[Subtasks]) -> Subtasks:
    return Subtasks(**{name: np.concatenate([r[name] for r in records]) for name in _DTYPES})


def traversal_stats(subtasks: Subtasks, depth: int) -> dict[str, float]:
    """Per layer: mean steps per sub-task, how often the layer's traversal reached g, and its sub-tasks'
    success."""
    out = {}
    layers, reached = subtasks["layer"], subtasks["reached"]
    for k in range(depth + 1):
        in_layer = layers == k
        if not in_layer.any():
            continue
        out[keys.AGENT_STEPS_LAYER + str(k)] = float(subtasks["steps"][in_layer].mean())
        # A layer's traversal succeeds when its last sub-task (the final goal g) is reached.
        last = in_layer & (subtasks["index"] == 2**k)
        if last.any():
            out[keys.AGENT_SUCCESS_LAYER + str(k)] = float(reached[last].mean())
        out[keys.AGENT_SUBTASK_SUCCESS_LAYER + str(k)] = float(reached[in_layer].mean())
    return out
