"""Where the paper is ambiguous, or its literal reading starves the agent: the choices, and presets.

Every such question is a CoPilotConfig knob (sweepable from a spec under the same name). This module
names the allowed values of each, and `PRESETS` the readings that go together: `paper_literal` is the
paper's (or, where the paper is silent, the public reference code's) reading of every one of them.
CoPilotConfig's defaults are the readings chosen by measurement (README, "Why these defaults").

No Ray import here: the sweep spec validates against these tuples before anything starts.
"""

from __future__ import annotations

from typing import Any

# Sub-task step limit: tau_max for every sub-task (paper) or tau_max * 2^(K-k) for layer k.
STEP_LIMITS = ("fixed", "scaled")
# After a failed sub-task the next one starts where the agent stopped (paper), at the missed sub-goal
# ("restart", when free), or the rest of the layer is dropped ("abort_layer").
AFTER_FAILURE = ("continue", "restart", "abort_layer")
# Reward for reaching a sub-goal of layer k: R / 2^k (paper Eq. 6) or R.
SUBTASK_REWARDS = ("halving", "uniform")
# The agent's blocked moves: free (paper), a penalty per blocked move, or a penalty and the end.
AGENT_COLLISIONS = ("none", "penalty", "terminate")
# What the agent's networks see: (state, goal) as in the paper's pi(a | s, g), or that plus goal -
# achieved goal (still a function of s and g; it makes "head for the goal" the same function everywhere).
AGENT_INPUTS = ("state_goal", "state_goal_delta")
# D_tau's tuple for a failed sub-task: (start, where it stopped, steps) as the paper says, or
# (start, sub-goal, a lower bound of the steps it needs).
FAILED_SUBTASK_COSTS = ("end_state", "lower_bound")
# The tree the agent traverses: a sample of pi_p (paper) or pi_p's mean.
TRAVERSAL_TREES = ("sampled", "mean")
# The actions behind the headline evaluation metrics (both are always logged).
EVAL_ACTIONS = ("deterministic", "sampled")

# CoPilotConfig's defaults for every reading: chosen by measurement on four-rooms (README, "Why these
# defaults"). Each entry says what the paper does instead.
DEFAULTS: dict[str, Any] = {
    "tau_max": 25,  # the paper's
    "step_limit": "fixed",  # the paper's
    # paper: "continue"; a failed sub-task put the agent off the path and the next sub-goal out of reach
    "after_failure": "restart",
    # paper: R / 2^k; a layer-5 reward of 1/32 is smaller than the entropy bonus SAC earns by not
    # reaching the sub-goal (the episode would end), so the finest sub-tasks were never learnt
    "subtask_reward": "uniform",
    "reward_scale": 1.0,  # the paper's
    "agent_collision": "none",  # the paper's
    "agent_collision_penalty": 0.0,
    "agent_input": "state_goal_delta",  # paper: (s, g); the delta is a function of both
    # paper: "end_state"; tau_hat then never sees a segment longer than the agent covered, so it
    # priced long segments like short ones and the finest segments drifted out of reach
    "failed_subtask_cost": "lower_bound",
    # paper: a sample of pi_p; with std 0.05 a third of the sampled layer-5 segments were out of reach
    "traversal_tree": "mean",
    # paper: 0; 1000 phases (~90 s, no env steps) gave ~85-90 % collision-free test plans before the
    # agent's first step
    "planner_warm_start": 1000,
    "eval_action": "deterministic",  # both are logged
    # paper (reference code): a fixed std 0.05; annealed to 0.015 the finest paths got 1.7x, not 3x,
    # the shortest path and an agent driving straight at each sub-goal followed 92 % of them, not 40 %
    "planner": {"std": 0.05, "noise": "absolute", "std_final": 0.015},
    # paper: SAC's default temperature 1; sparse sub-task rewards of R / 2^k drown in an entropy bonus
    # that starts at 1 (on an open maze: 0.00 test success after 8k env steps with 1.0, 0.74 with 0.02)
    "initial_alpha": 0.02,
    "target_entropy": "auto",
}

PRESETS: dict[str, dict[str, Any]] = {
    # The measured defaults again (undoes another preset; a sweep axis value).
    "default": DEFAULTS,
    "paper_literal": {
        "tau_max": 25,
        "step_limit": "fixed",
        "after_failure": "continue",
        "subtask_reward": "halving",
        "reward_scale": 1.0,
        "agent_collision": "none",
        "agent_collision_penalty": 0.0,
        "traversal_tree": "sampled",
        "agent_input": "state_goal",
        "failed_subtask_cost": "end_state",
        "planner_warm_start": 0,
        "eval_action": "deterministic",
        # The reference code's planner noise: a fixed absolute std.
        "planner": {"std": 0.05, "noise": "absolute", "std_final": None},
        # "For RL training with SAC, we use its default hyperparameters": SAC's initial temperature 1.
        "initial_alpha": 1.0,
        "target_entropy": "auto",
    },
    # Not a reading but the baseline CO-PILOT must beat: the same learner, replay and evaluation with
    # no planner (tree depth 0), one episode per task with the step budget of a finest traversal
    # (2^5 sub-tasks x 25 steps).
    "plain_sac": {**DEFAULTS, "tree_depth": 0, "tau_max": 800},
}
