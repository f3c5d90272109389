"""Settings of ``algorithm: her``: the SAC baseline's (copilot_ray.algorithms.sac.settings) plus
hindsight relabelling's ``her.n_sampled_goal`` and ``her.goal_selection``."""

from copilot_ray.algorithms.sac.settings import AGENT, HINDSIGHT, METRICS, combination_problems

SETTINGS = {s.key: s for s in (*AGENT, *HINDSIGHT)}

__all__ = ["METRICS", "SETTINGS", "combination_problems"]
