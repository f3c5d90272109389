"""The classical-planner curriculum as a sweep trial (the registry's third entry; imports Ray Tune)."""

from copilot_ray.algorithms.rrt_curriculum.algorithm import RRTCurriculum
from copilot_ray.trials.spec_trial import SpecTrial


class RRTCurriculumTrial(SpecTrial, RRTCurriculum):
    """RRTCurriculum as a sweep trial (see SpecTrial)."""
