"""SoRB as a sweep trial (the registry's third entry; imports Ray Tune)."""

from copilot_ray.algorithms.sorb.algorithm import SoRB
from copilot_ray.trials.spec_trial import SpecTrial


class SoRBTrial(SpecTrial, SoRB):
    """SoRB as a sweep trial (see SpecTrial)."""
