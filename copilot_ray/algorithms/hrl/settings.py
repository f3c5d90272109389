"""Every setting of the hierarchical-RL baseline (``algorithm: hrl``), declared once (no Ray here).

Task and evaluation settings are the SAC baseline's (same keys, rules and defaults: ``tau_max`` steps
per training episode and per test task, ``reward_scale`` times the goal env's sparse reward, the first
``eval_num_tasks`` test tasks every ``eval_interval`` iterations). The hierarchy's own settings are
``hrl.*``; each level's SAC settings are CO-PILOT's SAC settings under ``low.*`` and ``high.*``.

``hrl.subgoal_range`` is a fraction of the goal space's width, per dimension: the high level's offsets
lie in [-r x width_i, r x width_i] (so it needs a goal space with finite bounds). It is
environment-specific: on the open demo maze (speed 0.05) the agent covers 0.5 of the width in 10 steps,
on the default four-rooms maze (speed 0.0025) 0.025.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from copilot_ray import keys
from copilot_ray.algorithms.copilot import settings as copilot_settings
from copilot_ray.algorithms.sac import settings as sac_settings
from copilot_ray.settings import (
    Setting,
    bool_setting,
    choice_setting,
    float_setting,
    int_setting,
    sizes_setting,
)

LOW_REWARDS = ("dense", "sparse")
LEVELS = ("low", "high")

_SAC = sac_settings.SETTINGS
_C = copilot_settings.SETTINGS

TASK = [
    _SAC["tau_max"],
    replace(
        _SAC["task_batch_size"],
        doc="training episodes run side by side (one training task each) between two update phases",
    ),
    _SAC["reward_scale"],
    _SAC["agent_input"],
    _SAC["eval_interval"],
    _SAC["eval_every_env_steps"],
    _SAC["eval_num_tasks"],
    replace(
        _SAC["eval_action"],
        doc="the actions (both levels) behind the headline copilot/eval/success (both are always logged)",
    ),
    int_setting(
        "env_steps_per_iteration",
        "hrl",
        1000,
        "env steps per Tune iteration, at least (whole batches of episodes; the last one may overshoot)",
        1,
    ),
    replace(
        _SAC["num_steps_sampled_before_learning_starts"],
        target="hrl",
        doc="env steps of uniformly random actions (both levels) before the first update of either level",
    ),
    int_setting("replay_capacity", "hrl", 1_000_000, "low-level transitions kept (the high level: / c)", 1),
]
HIERARCHY = [
    int_setting("hrl.c", "hrl", 10, "env steps between two sub-goal proposals (HIRO's c)", 1),
    float_setting(
        "hrl.subgoal_range",
        "hrl",
        0.1,
        "largest sub-goal offset per goal dimension, as a fraction of the goal space's width",
        0.0,
        1.0,
        lo_open=True,
    ),
    choice_setting(
        "hrl.low_reward",
        "hrl",
        "dense",
        "the low level's reward: HIRO's -||achieved + offset - achieved'|| (never terminal), or the goal "
        "env's sparse reward for reaching the sub-goal (terminal)",
        LOW_REWARDS,
    ),
    bool_setting(
        "hrl.off_policy_correction",
        "hrl",
        True,
        "relabel replayed sub-goals by the candidate the current low level most likely acted on (HIRO)",
    ),
    int_setting(
        "hrl.num_candidates",
        "hrl",
        8,
        "sampled correction candidates around achieved_{t+c} - achieved_t (plus it and the original)",
        0,
    ),
]
_LEVEL_FIELDS = (
    "actor_lr",
    "critic_lr",
    "alpha_lr",
    "gamma",
    "initial_alpha",
    "target_entropy",
    "tau",
    "train_batch_size_per_learner",
)


def _level(level: str, ratio_key: str, ratio_doc: str) -> list[Setting]:
    """CO-PILOT's SAC settings for one level (`low.gamma`, ...) plus its nets and update ratio."""
    out = [replace(_C[k], key=f"{level}.{k}", target=level, on_cli=False, why="") for k in _LEVEL_FIELDS]
    out.append(
        sizes_setting(f"{level}.hidden", level, [256, 256], f"the {level} level's actor/critic hidden layers")
    )
    out.append(float_setting(f"{level}.{ratio_key}", level, 1.0, ratio_doc, 0.0))
    return out


LOW = _level("low", "updates_per_env_step", "low-level SAC gradient steps per env step")
HIGH = _level("high", "updates_per_transition", "high-level SAC gradient steps per high-level transition")

SETTINGS: dict[str, Setting] = {s.key: s for s in (*TASK, *HIERARCHY, *LOW, *HIGH)}

# Diagnostics only this algorithm logs, under keys.HRL_PREFIX (which MLflow tracking keeps).
_P = keys.HRL_PREFIX
SUBGOAL_REACHED = f"{_P}train/subgoal_reached"  # share of this iteration's segments ending at their sub-goal
CORRECTION_KEPT = f"{_P}correction/original_kept"  # share of corrected samples that kept the stored offset
LOW_QF_LOSS, HIGH_QF_LOSS = f"{_P}low/qf_loss", f"{_P}high/qf_loss"
LOW_ALPHA, HIGH_ALPHA = f"{_P}low/alpha", f"{_P}high/alpha"
EPISODE_RETURN_MEAN = "env_runners/episode_return_mean"  # RLlib's name: training episodes' mean return

METRICS: tuple[str, ...] = (
    *keys.validation_metrics(keys.EVAL_SUCCESS, keys.SUCCESS_DIRECT, keys.EVAL_SUCCESS_AUC, keys.EVAL_RETURN),
    keys.EVAL_SUCCESS,
    keys.EVAL_SUCCESS_AUC,
    keys.SUCCESS_DIRECT,
    keys.REACHED_DIRECT,
    keys.EVAL_RETURN,
    keys.ENV_STEPS,
    EPISODE_RETURN_MEAN,
    SUBGOAL_REACHED,
    CORRECTION_KEPT,
    LOW_QF_LOSS,
    HIGH_QF_LOSS,
    LOW_ALPHA,
    HIGH_ALPHA,
)


def max_iteration_env_steps(values: dict[str, Any]) -> int:
    """One iteration: batches of episodes until env_steps_per_iteration, the last batch whole."""
    get = lambda key: values.get(key, SETTINGS[key].default)  # noqa: E731
    return int(get("env_steps_per_iteration")) + int(get("task_batch_size")) * int(get("tau_max"))


def combination_problems(values: dict[str, Any]) -> list[tuple[tuple[str, ...], Any, str]]:
    """A sub-goal period longer than an episode is one proposal per episode: refused as a typo."""
    c = values.get("hrl.c", SETTINGS["hrl.c"].default)
    tau = values.get("tau_max", SETTINGS["tau_max"].default)
    if isinstance(c, int) and isinstance(tau, int) and c > tau:
        return [(("hrl.c", "tau_max"), {"hrl.c": c, "tau_max": tau}, "hrl.c must be <= tau_max")]
    return []
