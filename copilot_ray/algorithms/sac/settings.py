"""Every setting of the SAC and HER baselines (``algorithm: sac`` / ``algorithm: her``), declared once.

Both are CO-PILOT's agent without its planner: the same goal-conditioned SAC learner, replay, traversal
env and evaluation, one episode per training task (s0, g) of ``tau_max`` steps. Their settings are
CO-PILOT's agent-side ones (same keys, same rules), with a horizon of 800 steps by default: the step
budget of CO-PILOT's finest traversal on four-rooms (2^5 sub-tasks x 25 steps), so every method gets
the same steps per test task. HER adds ``her.n_sampled_goal`` and ``her.goal_selection``
(Stable-Baselines3's names and defaults).
"""

from __future__ import annotations

from dataclasses import replace

from copilot_ray import keys
from copilot_ray.algorithms.copilot import settings as copilot_settings
from copilot_ray.settings import choice_setting, int_setting

_C = copilot_settings.SETTINGS
GOAL_SELECTIONS = ("future", "final", "episode")  # as gc_sac.hindsight_buffer (no torch import here)

AGENT = [
    replace(
        _C["tau_max"],
        default=800,
        doc="steps per episode (one training task each); also the test tasks' step budget",
    ),
    replace(_C["task_batch_size"], default=4, doc="episodes per iteration (one training task each)", why=""),
    _C["reward_scale"],
    _C["agent_collision"],
    _C["agent_collision_penalty"],
    _C["agent_input"],
    _C["subtasks_per_sample"],
    _C["eval_interval"],
    _C["eval_every_env_steps"],
    _C["eval_num_tasks"],
    _C["eval_action"],
    *(s for s in _C.values() if s.target == "training"),
    _C["updates_per_env_step"],
]
HINDSIGHT = [
    int_setting(
        "her.n_sampled_goal",
        "her",
        4,
        "relabelled goals per real one (SB3's default 4: 80 % of each batch relabelled)",
        1,
    ),
    choice_setting(
        "her.goal_selection",
        "her",
        "future",
        "where a relabelled goal comes from: later in the episode, its end, or anywhere in it",
        GOAL_SELECTIONS,
    ),
]

SETTINGS = {s.key: s for s in AGENT}

# What a comparison tunes (`search: declared`): the learner's space CO-PILOT's agent gets too.
LEARNER_SEARCH_SPACE = copilot_settings.LEARNER_SEARCH_SPACE
SEARCH_SPACE: dict[str, dict] = dict(LEARNER_SEARCH_SPACE)
# What a run logs that a sweep may optimise or stop on.
METRICS: tuple[str, ...] = (
    *keys.validation_metrics(keys.EVAL_SUCCESS, keys.SUCCESS_DIRECT, keys.EVAL_SUCCESS_AUC, keys.EVAL_RETURN),
    keys.EVAL_SUCCESS,
    keys.SUCCESS_DIRECT,
    keys.EVAL_SUCCESS_AUC,
    keys.ENV_STEPS,
    "env_runners/episode_return_mean",  # RLlib's
)


def max_iteration_env_steps(values) -> int:
    """One iteration: an episode of at most tau_max steps on each of task_batch_size training tasks."""
    get = lambda key: values.get(key, SETTINGS[key].default)  # noqa: E731
    return int(get("task_batch_size")) * int(get("tau_max"))


def combination_problems(values):
    """The update-to-data ratio is set one way only (as for CO-PILOT)."""
    return copilot_settings.combination_problems(values)
