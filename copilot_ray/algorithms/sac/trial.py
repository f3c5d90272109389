"""The SAC and HER baselines as sweep trials (the registry's third entry; imports Ray Tune)."""

from copilot_ray.algorithms.sac.algorithm import GoalSAC
from copilot_ray.trials.spec_trial import SpecTrial


class GoalSACTrial(SpecTrial, GoalSAC):
    """GoalSAC (SAC or HER, by its config) as a sweep trial (see SpecTrial)."""
