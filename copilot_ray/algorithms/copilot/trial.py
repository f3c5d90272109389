"""CoPilotTrial: CO-PILOT as a sweep trial (the registry's third entry; imports Ray Tune)."""

from copilot_ray.algorithms.copilot.algorithm import CoPilot
from copilot_ray.trials.spec_trial import SpecTrial


class CoPilotTrial(SpecTrial, CoPilot):
    """CoPilot as a sweep trial (see SpecTrial)."""
