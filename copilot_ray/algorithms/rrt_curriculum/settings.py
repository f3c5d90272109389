"""Every setting of the classical-planner curriculum (``algorithm: rrt_curriculum``), declared once.

CO-PILOT's agent, traversal and evaluation (its settings and defaults, read from
copilot_ray.algorithms.copilot.settings) on trees cut from RRT* paths (copilot_ray.planning.rrt_trees):
tree depth K, repetitions b and the traversal readings are CO-PILOT's; the planner, its cost model and
the alpha schedule do not exist here. RRT*'s checks are a privilege (``collision_checks``, counted).

``tau_max`` (the steps of one finest sub-task) defaults to null: 800 / 2^K, so that a test task's budget
(tau_max x 2^K, what every method gets: the SAC baseline's 800 steps on four-rooms) stays the same
whatever K the search tries; K = 5 gives CO-PILOT's 25.

No Ray import here: sweep specs are validated against this table before anything starts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from copilot_ray import keys
from copilot_ray.algorithms.copilot import settings as copilot_settings
from copilot_ray.algorithms.sac import settings as agent_settings
from copilot_ray.privileges import COLLISION_CHECKS
from copilot_ray.settings import Setting, float_setting, is_int

# A whole task's steps: the agent-only baselines' episode, and every method's test budget.
TASK_STEPS = int(agent_settings.SETTINGS["tau_max"].default)

_COPILOT = copilot_settings.SETTINGS
_SHARED = (
    "tree_depth",
    "repetitions",
    "task_batch_size",
    "step_limit",
    "after_failure",
    "subtask_reward",
    "reward_scale",
    "agent_collision",
    "agent_collision_penalty",
    "agent_input",
    "subtasks_per_sample",
    "eval_interval",
    "eval_every_env_steps",
    "eval_num_tasks",
    "eval_action",
)
_TAU_MAX = Setting(
    "tau_max",
    "int",
    "agent",
    None,
    f"step limit of one finest sub-task; null: {TASK_STEPS} / 2^K, a test task's budget whatever K",
    lambda v: v is None or (is_int(v) and v >= 1),
    "null or an integer >= 1",
)
_RRT = [
    float_setting(
        "curriculum.rrt_time_s",
        "curriculum",
        0.5,
        "RRT*'s planning time per task (each task planned once, its tree kept)",
        0.0,
        lo_open=True,
        why="on 40 four-rooms VALIDATION tasks RRT* solved all within 0.25 s, 0.5 s or 1 s (0.95 within 0.1 s), "
        "its paths 1.5 % / 0.4 % longer at 0.25 / 0.5 s than at 1 s",
    ),
]
SETTINGS: dict[str, Setting] = {
    **{key: _COPILOT[key] for key in _SHARED},
    "tau_max": _TAU_MAX,
    **{s.key: s for s in _RRT},
    **{s.key: s for s in agent_settings.LEARNER},
}
# RRT* plans every tree with the map.
PRIVILEGES = (COLLISION_CHECKS,)
LABELS = {"K": "tree_depth", "b": "repetitions"}
GPU_LEARNER = True
SEED_STACK = True  # the agent's stacked update, as CO-PILOT's

METRICS: tuple[str, ...] = (
    *keys.TREE_AGENT_EVAL_METRICS,  # validation figures for searchers, test figures reported
    keys.AGENT_STEPS_LAYER + "<k>",
    keys.AGENT_SUCCESS_LAYER + "<k>",
    keys.CURRICULUM_RRT_TASKS,
    keys.CURRICULUM_RRT_UNSOLVED,
    keys.ENV_STEPS,
    *keys.PATH_METRICS,
)

# The learner's space (CO-PILOT's agent gets the same) plus the curriculum's structure: its depth K
# (tau_max follows K, so every K keeps the test budget).
SEARCH_SPACE: dict[str, dict] = {
    **agent_settings.LEARNER_SEARCH_SPACE,
    "tree_depth": {"categorical": [3, 4, 5]},
}


def tau_max_of(values: Mapping[str, Any]) -> int:
    """The finest sub-tasks' step limit: `tau_max`, or TASK_STEPS / 2^K when it is null."""
    tau = values.get("tau_max", SETTINGS["tau_max"].default)
    depth = int(values.get("tree_depth", SETTINGS["tree_depth"].default))
    return int(tau) if tau is not None else max(1, TASK_STEPS // 2**depth)


def max_iteration_env_steps(values: Mapping[str, Any]) -> int:
    """CO-PILOT's bound (every sub-task of every tree runs to its limit) at this tau_max."""
    return copilot_settings.max_iteration_env_steps({**values, "tau_max": tau_max_of(values)})


def max_env_steps_past_budget(values: Mapping[str, Any]) -> int:
    """One repetition's worth less one (an iteration ends at the repetition that reaches the budget)."""
    return copilot_settings.max_env_steps_past_budget({**values, "tau_max": tau_max_of(values)})


def combination_problems(values: Mapping[str, Any]) -> list[tuple[tuple[str, ...], Any, str]]:
    return agent_settings.combination_problems(values)
