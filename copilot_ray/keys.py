"""Names that more than one module spells, defined once: metric keys, MLflow tags, Tune config keys and
artifact names.

Metric keys are the ``/``-joined paths of an RLlib result (``result["copilot"]["eval"]["success_planned"]``
is ``copilot/eval/success_planned``), which is also the name MLflow stores the metric under. Keys ending
in ``_layer_`` take a tree layer k = 0..K appended (``PLANNER_COST_LAYER + "3"``). ``metric_path`` turns a
key into the tuple ``MetricsLogger.log_value`` / ``peek`` take; ``result_value`` reads a key from a nested
or a flattened result.

Standard library only: the spec checks, ``--check`` and the analysis import this without Ray or torch.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

# ================================================================================================ results
# RLlib / Tune: the x axis of every curve (MLflow's `step`), Tune's time attribute and stop criterion.
ENV_STEPS = "env_runners/num_env_steps_sampled_lifetime"
TRAINING_ITERATION = "training_iteration"
TIME_TOTAL_S = "time_total_s"
NODE_ID = "node_id"  # the Ray node a sweep trial's result came from (a string; Tune's result.json)

# The result namespaces a trial's MLflow run keeps (flattened with "/"): every algorithm's own
# diagnostics must sit under one of them, or they never reach MLflow.
HRL_PREFIX = "hrl/"  # copilot_ray.algorithms.hrl's own diagnostics (its settings module names them)
TRACKED_PREFIXES = (
    "copilot/",
    "sorb/",  # SoRB's graph (the names below)
    HRL_PREFIX,
    "paths/",
    "env_runners/",
    "learners/default_policy/",
    "timers/",
)

# RLlib's own bookkeeping inside those namespaces (connector and env-runner timers, throughputs, weight
# sequence numbers: ~100 per trial): kept out of MLflow unless a spec asks (tracking.rllib_timers).
RLLIB_INTERNAL_PREFIXES = ("timers/", "env_runners/sample", "env_runners/time_between_sampling")
RLLIB_INTERNAL_PARTS = ("_timer", "connector", "throughput", "weights_seq_no")


def is_rllib_internal(key: str) -> bool:
    return key.startswith(RLLIB_INTERNAL_PREFIXES) or any(part in key for part in RLLIB_INTERNAL_PARTS)


# CO-PILOT's own metrics (copilot_ray.algorithms.copilot), all under "copilot/".
COPILOT_PREFIX = "copilot/"
ALPHA = "copilot/alpha"
DTAU_SIZE = "copilot/dtau/size"
COST_MODEL_LOSS = "copilot/cost_model/loss"
TIME_PREFIX = "copilot/time/"  # wall seconds per phase of an iteration
PLANNING_SHARE = "copilot/time/planning_share"
AGENT_SAC_UPDATES = "copilot/agent/sac_updates"  # SAC gradient steps in the iteration

# Evaluation on the held-out TEST tasks (what reports show): the headline action's figures, and per
# action mode (`eval_by_action`: copilot/eval/<action>/<name>). The same figures on the VALIDATION tasks
# (what searchers, schedulers and probes read) are under copilot/validation/ (`validation_key`).
EVAL_PREFIX = "copilot/eval/"
VALIDATION_PREFIX = "copilot/validation/"
SUCCESS_PLANNED = "copilot/eval/success_planned"
SUCCESS_DIRECT = "copilot/eval/success_direct"
# The one figure every algorithm reports (Fig. 2a / 4a compare it): CO-PILOT's success_planned, the
# agent-only baselines' (SAC, HER, PPO) success_direct, SoRB's success along its graph's waypoints.
EVAL_SUCCESS = "copilot/eval/success"
SUCCESS_METRICS = (EVAL_SUCCESS, SUCCESS_PLANNED, SUCCESS_DIRECT)
# The paper's Fig. 2d (Ant maze): the average return on the test tasks of the same rollout as
# EVAL_SUCCESS, with the task reward R (reward_scale x the goal env's goal_reward) for reaching the goal.
EVAL_RETURN = "copilot/eval/return"
# The paper's Fig. 3 (stump-track walker; envs whose goal env has `mastery`): the share of evaluation
# track distributions mastered (mean walker return over their tracks > 230), and that mean return.
EVAL_MASTERED = "copilot/eval/mastered"
EVAL_ENV_RETURN = "copilot/eval/env_return"
# What the analysis draws against env steps.
CURVE_METRICS = (*SUCCESS_METRICS, EVAL_RETURN, EVAL_MASTERED)
REACHED_PLANNED = "copilot/eval/reached_planned"
REACHED_DIRECT = "copilot/eval/reached_direct"
SUBGOALS_REACHED_PLANNED = "copilot/eval/subgoals_reached_planned"
PLANNED_COLLISION_FREE = "copilot/eval/planned_collision_free"
# The classical-planner curriculum's RRT*: tasks planned so far, and those it did not solve in its time.
CURRICULUM_RRT_TASKS = "copilot/curriculum/rrt_tasks"
CURRICULUM_RRT_UNSOLVED = "copilot/curriculum/rrt_unsolved"
# SoRB's search graph at each evaluation: edges kept, waypoints per test path (its start and goal too).
SORB_GRAPH_EDGES = "sorb/graph_edges"
SORB_WAYPOINTS = "sorb/waypoints_mean"
SORB_GRAPH_S = "sorb/graph_s"
# Set by the sweep's trial on every result: 1 when this iteration evaluated, 0 when the success
# metrics repeat the last evaluation.
EVAL_FRESH = "copilot/eval/fresh"
# Area under the success curve so far, normalised by its env-step span (trapezoid over the evaluations):
# one number that rewards learning early and ending high (a searcher's objective on validation tasks).
EVAL_SUCCESS_AUC = "copilot/eval/success_auc"
EVAL_ACTIONS = ("deterministic", "sampled")

# What a method uses that its baselines may not (copilot_ray.privileges), counted since the run began:
# ground-truth collision checks, resets of the agent to a state other than a task's start, and
# questions to the map whether a state is free. Every algorithm logs all three (0 where it has none).
PRIVILEGE_PREFIX = "copilot/privileges/"
PRIVILEGE_COLLISION_CHECKS = "copilot/privileges/collision_checks"
PRIVILEGE_RESETS = "copilot/privileges/resets"
PRIVILEGE_MAP_QUERIES = "copilot/privileges/map_queries"
PRIVILEGE_COUNTS = (PRIVILEGE_COLLISION_CHECKS, PRIVILEGE_RESETS, PRIVILEGE_MAP_QUERIES)

# The planner (PPO over sub-goal trees).
PLANNER_PREFIX = "copilot/planner/"
PLANNER_COST_LAYER = "copilot/planner/cost_layer_"
PLANNER_ROLLED_BACK = "copilot/planner/rolled_back"
PLANNER_STD = "copilot/planner/std"
PLANNER_APPROX_KL_MAX = "copilot/planner/approx_kl_max"
PLANNER_NONFINITE_SKIPPED = "copilot/planner/nonfinite_skipped"
# the warm start's last phase, finest layer: rows that share a seed's warm start log the same value
PLANNER_WARM_START_COST = "copilot/planner/warm_start_cost"

# The agent's traversals during training.
AGENT_STEPS_LAYER = "copilot/agent/steps_layer_"
AGENT_SUCCESS_LAYER = "copilot/agent/success_layer_"
AGENT_SUBTASK_SUCCESS_LAYER = "copilot/agent/subtask_success_layer_"
# Sub-tasks of this iteration that an env runner took with it when it died (RLlib restores the runner
# before the next iteration; these are not traversed, so not learned from and not in D_tau).
AGENT_SUBTASKS_LOST = "copilot/agent/subtasks_lost"

# Diagnostics (copilot_ray.planning.plan_diagnostics): why a run does (not) learn.
DIAG_PREFIX = "copilot/diag/"
DIAG_Q_MEAN = "copilot/diag/q_mean"
DIAG_SUCCESS_AFTER_REACHED = "copilot/diag/success_after_reached"
DIAG_SUCCESS_AFTER_FAILED = "copilot/diag/success_after_failed"
DIAG_SUBGOAL_IN_OBSTACLE_LAYER = "copilot/diag/subgoal_in_obstacle_layer_"
DIAG_SEGMENT_LENGTH_LAYER = "copilot/diag/segment_length_layer_"
DIAG_REACHABLE_LENGTH_LAYER = "copilot/diag/reachable_length_layer_"
DIAG_SEGMENT_UNREACHABLE_LAYER = "copilot/diag/segment_unreachable_layer_"
DIAG_FIRST_SUBTASK_TRIVIAL = "copilot/diag/first_subtask_trivial"
DIAG_SUBTASK_COLLIDED = "copilot/diag/subtask_collided"
DIAG_DTAU_TUPLE_LENGTH_MEAN = "copilot/diag/dtau_tuple_length_mean"
DIAG_DTAU_TUPLE_LENGTH_MAX = "copilot/diag/dtau_tuple_length_max"
# How well the planner's time cost tracks the agent's: a repetition's new D_tau tuples scored before
# tau_hat is refit on them (held out), in env steps: mean |tau_hat - measured|, mean (tau_hat - measured),
# and the Euclidean cost's mean |distance / step distance - measured| beside it (what alpha = 1 plans on).
DIAG_TAU_HAT_ERROR = "copilot/diag/tau_hat_error_steps"
DIAG_TAU_HAT_BIAS = "copilot/diag/tau_hat_bias_steps"
DIAG_EUCLIDEAN_ERROR = "copilot/diag/euclidean_error_steps"

# Planners scored as motion planners (copilot_ray.planning.path_metrics; the paper's Fig. 4b/4c): every
# method that produces paths (RRT*, SGT-PG, CO-PILOT's finest layer) logs these on the same test tasks.
PATHS_PREFIX = "paths/"
PATH_SUCCESS = "paths/success"  # share of test tasks with a collision-free path to the goal radius
PATH_LENGTH = "paths/length"  # mean length (env distance) of the successful paths
PATH_COLLISION_CHECKS = "paths/collision_checks"  # checks spent so far (training + planning)
PATH_SUCCESS_VS_RRT = "paths/success_vs_rrt"  # success / RRT*'s on the same tasks
PATH_LENGTH_VS_RRT = "paths/length_vs_rrt"  # mean of length / RRT*'s, tasks both solved
PATH_CHECKS_VS_RRT = "paths/collision_checks_vs_rrt"  # checks / RRT*'s total on the same tasks
PATH_TASKS = "paths/tasks"  # test tasks scored
PLANNER_UPDATES = "paths/planner_updates"  # planner phases so far (planner-only algorithms)
PATH_METRICS = (
    PATH_SUCCESS,
    PATH_LENGTH,
    PATH_COLLISION_CHECKS,
    PATH_SUCCESS_VS_RRT,
    PATH_LENGTH_VS_RRT,
    PATH_CHECKS_VS_RRT,
)

# ================================================================================================ MLflow
# Tags of a sweep's runs (copilot_ray.tracking writes them, analysis.load reads them).
SWEEP_TAG = "copilot.sweep"
ROLE_TAG = "copilot.role"
ROLE_SWEEP = "sweep"  # ROLE_TAG of the parent run, one per sweep
ROLE_TRIAL = "trial"  # ROLE_TAG of a child run, one per trial
# The parent run's param naming its searcher; searchers in SEARCHES choose configurations (by validation
# figures), so what a search shows (its summary, its report) holds no test-task figure.
SEARCHER_PARAM = "searcher"
SEARCHES = ("optuna",)
# The parent run's param holding the sweep's env-step budget (the report reads final success there).
BUDGET_PARAM = "stop.env_steps"
TRIAL_ID_TAG = "copilot.trial_id"
ERROR_TAG = "copilot.error"  # a FAILED trial run: the last line of its error (exception and message)
CONFIG_KEY_TAG = "copilot.config_key"
# "<algorithm> <config key>": one configuration of an experiment whose parts run several algorithms (the
# MLflow view groups a trial run's seeds by it; copilot_ray.mlflow_view)
CONFIGURATION_TAG = "copilot.configuration"
TUNE_PATH_TAG = "copilot.tune_path"
PARENT_TAG = "mlflow.parentRunId"
GIT_COMMIT_TAG = "git_commit"
SEED_TAG = "seed"
# The axes a run is labelled by (sweep child runs and `python -m copilot_ray.train` runs).
ALGORITHM_TAG = "algorithm"
ENV_TAG = "env"
K_TAG = "K"
B_TAG = "b"
ALPHA_SCHEDULE_TAG = "alpha_schedule"
PRESET_TAG = "preset"
VARIANT_TAG = "variant"
PRIVILEGES_TAG = "copilot.privileges"  # comma-separated privilege names (copilot_ray.privileges), or "none"
AXIS_TAGS = (ALGORITHM_TAG, ENV_TAG, VARIANT_TAG, PRESET_TAG, K_TAG, B_TAG, ALPHA_SCHEDULE_TAG)  # label order

# Artifacts. TREES_DIR is also the folder the algorithm writes under its logdir.
TREES_DIR = "copilot_trees"
CHECKPOINT_ARTIFACT = "checkpoint"
CONFIG_ARTIFACT = "config.yaml"
ERROR_ARTIFACT = "error"
SPEC_ARTIFACT = "spec.yaml"
RESOLVED_SPEC_ARTIFACT = "spec.resolved.yaml"
SUMMARY_ARTIFACT = "summary.md"
REPORT_ARTIFACT = "report"

# ================================================================================================ Tune
# Keys of a sweep trial's flat Tune config besides the searched dotted params.
SPEC_PATH_KEY = "_spec_path"  # the (resolved) spec the trial belongs to
SEED_PARAM = "seed"  # also the MLflow param
# A stacked trial (spec `seeds_per_trial` > 1) has `_seeds: [..]` instead of `seed`; its results carry
# each seed's metrics under SEED_RESULTS ({seed: {metric: value}}) and its failed seeds' errors under
# SEED_ERRORS ({seed: error}); copilot_ray.algorithms.sac.trial.
SEEDS_KEY = "_seeds"
PLAN_SEEDS = "seeds"  # a stacked trial's seeds in a spec's `trial_plan()` (not a setting)
SEED_RESULTS = "seed_results"
SEED_ERRORS = "seed_errors"
VARIANT_PARAM = "variant"
ENV_PARAM = "env.id"  # a trial's env when the spec lists several (`env: {id: [..]}`): a grid axis


# ================================================================================================ helpers
def metric_path(key: str) -> tuple[str, ...]:
    """``"copilot/eval/success_planned"`` -> ``("copilot", "eval", "success_planned")``."""
    return tuple(key.split("/"))


def eval_leaf(key: str) -> str:
    """An evaluation key's name under ``copilot/eval/``: ``copilot/eval/success_planned`` -> ``success_planned``."""
    if not key.startswith(EVAL_PREFIX):
        raise ValueError(f"{key!r} is not an evaluation metric ({EVAL_PREFIX}...)")
    return key[len(EVAL_PREFIX) :]


def validation_key(key: str) -> str:
    """A test-set evaluation key's validation-set twin: ``copilot/eval/success`` ->
    ``copilot/validation/success``."""
    if not key.startswith(EVAL_PREFIX):
        raise ValueError(f"{key!r} is not an evaluation metric ({EVAL_PREFIX}...)")
    return VALIDATION_PREFIX + key[len(EVAL_PREFIX) :]


def validation_metrics(*test_keys: str) -> tuple[str, ...]:
    """The validation twins of `test_keys` (what an algorithm's METRICS offers searchers)."""
    return tuple(validation_key(k) for k in test_keys)


# What an agent that traverses sub-goal trees offers at evaluation (CO-PILOT, the RRT* curriculum):
# searchers, schedulers and probes read the validation tasks' figures; the test tasks' are reported.
TREE_AGENT_EVAL_METRICS: tuple[str, ...] = (
    *validation_metrics(EVAL_SUCCESS, SUCCESS_PLANNED, SUCCESS_DIRECT, EVAL_SUCCESS_AUC, EVAL_RETURN),
    EVAL_SUCCESS,
    SUCCESS_PLANNED,
    SUCCESS_DIRECT,
    EVAL_SUCCESS_AUC,
)


def is_test_metric(key: str) -> bool:
    """Whether `key` is a figure of the test tasks (evaluation or path metrics): never a searcher's."""
    return key.startswith((EVAL_PREFIX, PATHS_PREFIX))


def eval_by_action(key: str, action: str) -> str:
    """An evaluation key for one action mode: ``copilot/eval/success_planned`` ->
    ``copilot/eval/<action>/success_planned``."""
    if not key.startswith(EVAL_PREFIX):
        raise ValueError(f"{key!r} is not an evaluation metric ({EVAL_PREFIX}...)")
    return f"{EVAL_PREFIX}{action}/{key[len(EVAL_PREFIX) :]}"


def result_value(result: Mapping[str, Any], key: str, default: Any = None) -> Any:
    """``result['a/b/c']`` from a nested or a flattened result."""
    if key in result:
        return result[key]
    node: Any = result
    for part in key.split("/"):
        if not isinstance(node, Mapping) or part not in node:
            return default
        node = node[part]
    return node
