"""CO-PILOT as an RLlib Algorithm: config, algorithm, traversal env."""

from copilot_ray.algorithms.copilot.algorithm import CoPilot
from copilot_ray.algorithms.copilot.config import CoPilotConfig

__all__ = ["CoPilot", "CoPilotConfig"]
