"""The PPO baseline as a sweep trial (the registry's third entry; imports Ray Tune)."""

from copilot_ray import keys
from copilot_ray.algorithms.ppo.algorithm import GoalPPO
from copilot_ray.trials.spec_trial import SpecTrial


class GoalPPOTrial(SpecTrial, GoalPPO):
    """GoalPPO as a sweep trial (see SpecTrial); it has no plan, so no success_planned."""

    eval_metrics = (keys.EVAL_SUCCESS, keys.SUCCESS_DIRECT, keys.EVAL_RETURN)
