"""Every setting of the goal-conditioned SAC agent, declared once: the SAC baseline's (``algorithm:
sac``), and the agent side of every algorithm built on it (HER, SoRB, CO-PILOT; HRL's levels and PPO's
task settings reuse some).

The agent runs episodes on training tasks (s0, g) through the traversal env (one episode = one
sub-task: for SAC the whole task, for CO-PILOT a planned segment), learns with the fast goal-conditioned
SAC learner and is evaluated on the same validation and test tasks as every method. SAC's horizon is 800
steps by default: the step budget of CO-PILOT's finest traversal on four-rooms (2^5 sub-tasks x 25
steps), so every method gets the same steps per test task. HER adds ``her.n_sampled_goal`` and
``her.goal_selection`` (Stable-Baselines3's names and defaults).

Targets (where `GoalSACConfig.from_settings` puts a value): ``agent`` -> `.agent(key=...)`, ``training``
-> `.training(key=...)` (RLlib SAC's own), ``her`` -> `.hindsight(field=...)`.

No Ray import here: sweep specs are validated against this table before anything starts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from copilot_ray import keys
from copilot_ray.privileges import MAP_QUERIES, RESET_TO_STATE
from copilot_ray.settings import (
    Setting,
    bool_setting,
    choice_setting,
    float_setting,
    int_setting,
    is_int,
    is_number,
)

AGENT_COLLISIONS = ("none", "penalty", "terminate")
STEP_LIMITS = ("fixed", "scaled")
AFTER_FAILURE = ("continue", "restart", "abort_layer")
SUBTASK_REWARDS = ("halving", "uniform")
AGENT_INPUTS = ("state_goal", "state_goal_delta")
EVAL_ACTIONS = keys.EVAL_ACTIONS
GOAL_SELECTIONS = ("future", "final", "episode")  # as gc_sac.hindsight_buffer (no torch import here)

# ------------------------------------------------------------------------------------- the table
# What one episode is and how it is rewarded.
TASKS = [
    int_setting(
        "tau_max",
        "agent",
        800,
        "steps per episode (one training task each); also the test tasks' step budget",
        1,
    ),
    Setting(
        "train_episode_steps",
        "int",
        "agent",
        None,
        "steps per training episode; null: tau_max (the test tasks' budget stays tau_max whatever this is)",
        lambda v: v is None or (is_int(v) and v >= 1),
        "null or an integer >= 1",
    ),
    int_setting("task_batch_size", "agent", 4, "episodes per iteration (one training task each)", 1),
    float_setting(
        "reward_scale",
        "agent",
        1.0,
        "R: multiplies the goal env's reward (paper: 1 in the maze)",
        0.0,
        lo_open=True,
    ),
    choice_setting(
        "agent_collision",
        "agent",
        "none",
        "a blocked move of the agent: free, a penalty, or a penalty and the end of the sub-task",
        AGENT_COLLISIONS,
    ),
    float_setting(
        "agent_collision_penalty",
        "agent",
        0.0,
        "reward subtracted per blocked move (agent_collision penalty/terminate)",
        0.0,
    ),
    choice_setting(
        "agent_input",
        "agent",
        "state_goal_delta",
        "what the agent's networks see: (state, sub-goal), or that plus sub-goal - achieved goal",
        AGENT_INPUTS,
    ),
    int_setting(
        "subtasks_per_sample", "agent", 64, "sub-tasks per env runner between two learner updates", 1
    ),
]
EVALUATION = [
    int_setting(
        "eval_interval",
        "agent",
        1,
        "iterations between evaluations (0: never); ignored when eval_every_env_steps is set",
        0,
    ),
    int_setting(
        "eval_every_env_steps",
        "agent",
        0,
        "evaluate at the end of every iteration that passes another multiple of this many env steps (an "
        "iteration of several repetitions ends at the one that passes it), so that methods with different "
        "iteration sizes are evaluated on one cadence (0: use eval_interval)",
        0,
    ),
    int_setting(
        "eval_num_tasks",
        "agent",
        100,
        "validation and test tasks per evaluation (the paper's test set has 100)",
        1,
    ),
    choice_setting(
        "eval_action",
        "agent",
        "deterministic",
        "the actions behind the headline copilot/eval/success_* (both are always logged)",
        EVAL_ACTIONS,
        why="which actions the headline metrics use; both are always logged",
    ),
]
LEARNER = [
    bool_setting(
        "fast_learner",
        "agent",
        True,
        "our flat-buffer SAC learner (false: RLlib's stock SAC module, learner and buffer, ~10x slower)",
    ),
    # How fast, not what is learned: spec keys so that a sweep can run the paths side by side (the
    # learning check of the fused update and the lean loop is such a sweep).
    bool_setting(
        "fused_update",
        "agent",
        True,
        "the fast learner's whole SAC step, replay sampling included, as one function on the learner's "
        "device (one CUDA graph on a GPU); false: the batch path before it, 16 steps per learner call",
    ),
    bool_setting(
        "lean_traversal",
        "agent",
        True,
        "sample sub-tasks with the lean env runner (TraversalEnvRunner: the same episodes without RLlib's "
        "per-step connector pipelines); false: RLlib's own env runner",
    ),
    float_setting(
        "updates_per_env_step",
        "agent",
        None,
        "SAC gradient steps per env step; null: from training_intensity when set, else 1.0",
        0.0,
        lo_open=True,
        optional=True,
    ),
    float_setting("actor_lr", "training", 3e-4, "SAC actor learning rate (SB3's default)", 0.0, lo_open=True),
    float_setting("critic_lr", "training", 3e-4, "SAC critic learning rate", 0.0, lo_open=True),
    float_setting("alpha_lr", "training", 3e-4, "SAC temperature learning rate", 0.0, lo_open=True),
    float_setting("gamma", "training", 0.99, "discount", 0.0, 1.0, lo_open=True),
    float_setting(
        "initial_alpha",
        "training",
        0.02,
        "SAC's initial entropy temperature",
        0.0,
        lo_open=True,
        why="SAC's default temperature swamps sparse sub-task rewards (open maze: 0.00 vs 0.74 test success "
        "at 8k env steps)",
    ),
    Setting(
        "target_entropy",
        "float",
        "training",
        "auto",
        'the entropy SAC tunes its temperature towards ("auto": -|A|)',
        lambda v: v == "auto" or is_number(v),
        '"auto" or a number',
        why="the paper's (SAC's default)",
    ),
    float_setting("tau", "training", 0.005, "target network update rate", 0.0, 1.0, lo_open=True),
    int_setting("train_batch_size_per_learner", "training", 256, "SAC batch size", 1),
    float_setting(
        "training_intensity",
        "training",
        None,
        "RLlib's update-to-data ratio: replayed per sampled timesteps (= updates_per_env_step x batch size)",
        0.0,
        lo_open=True,
        optional=True,
    ),
    int_setting(
        "num_steps_sampled_before_learning_starts",
        "training",
        1000,
        "env steps before the first SAC update",
        0,
    ),
]
AGENT: list[Setting] = [*TASKS, *EVALUATION, *LEARNER]
# How the traversal env runs the sub-tasks of a tree (CO-PILOT's readings, CO-PILOT's settings; declared
# here because the traversal env implements them; with the agent alone, one sub-task per task, none of
# them changes anything).
TREE_TRAVERSAL = [
    choice_setting(
        "step_limit",
        "copilot",
        "fixed",
        "sub-task step limit: tau_max for every sub-task, or tau_max x 2^(K-k) for layer k",
        STEP_LIMITS,
    ),
    choice_setting(
        "after_failure",
        "copilot",
        "continue",
        "after a failed sub-task the next starts where the agent stopped, at the missed sub-goal (when free), "
        "or the layer ends",
        AFTER_FAILURE,
        # restart puts the agent at the missed sub-goal after asking the map whether it is free.
        grants=lambda v: (RESET_TO_STATE, MAP_QUERIES) if v == "restart" else (),
    ),
    choice_setting(
        "subtask_reward",
        "copilot",
        "uniform",
        "reward for reaching a layer-k sub-goal: R / 2^k (Eq. 6) or R",
        SUBTASK_REWARDS,
    ),
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

# What a comparison tunes (`search: declared` in a spec; rl-zoo style, each algorithm's space next to
# its settings): the learner's learning rates and discount, which CO-PILOT's agent gets too. Every
# default lies inside its range (an Optuna study tries the defaults first).
LEARNER_SEARCH_SPACE: dict[str, dict] = {
    "actor_lr": {"float": [1e-4, 1e-3], "log": True},
    "critic_lr": {"float": [1e-4, 1e-3], "log": True},
    "gamma": {"categorical": [0.98, 0.99, 0.995]},
}
SEARCH_SPACE: dict[str, dict] = dict(LEARNER_SEARCH_SPACE)
# An RLlib learner: on the trial's GPU share when the spec asks for one (resources.gpus_per_trial).
GPU_LEARNER = True
# Seeds of one configuration can share one trial and one stacked update (a spec's seeds_per_trial).
SEED_STACK = True

# What a run logs that a sweep may optimise or stop on.
METRICS: tuple[str, ...] = (
    *keys.validation_metrics(keys.EVAL_SUCCESS, keys.SUCCESS_DIRECT, keys.EVAL_SUCCESS_AUC, keys.EVAL_RETURN),
    keys.EVAL_SUCCESS,
    keys.SUCCESS_DIRECT,
    keys.EVAL_SUCCESS_AUC,
    keys.ENV_STEPS,
    "env_runners/episode_return_mean",  # RLlib's
)


def max_iteration_env_steps(values: Mapping[str, Any]) -> int:
    """One iteration: an episode of at most train_episode_steps (else tau_max) steps on each of
    task_batch_size training tasks."""
    get = lambda key: values.get(key, SETTINGS[key].default)  # noqa: E731
    return int(get("task_batch_size")) * int(get("train_episode_steps") or get("tau_max"))


def combination_problems(values: Mapping[str, Any]) -> list[tuple[tuple[str, ...], Any, str]]:
    """Values valid one by one that clash together: the update-to-data ratio set two ways."""
    both = ("updates_per_env_step", "training_intensity")
    if all(values.get(k) is not None for k in both):
        return [(both, {k: values[k] for k in both}, "both set the update-to-data ratio; set one")]
    return []
