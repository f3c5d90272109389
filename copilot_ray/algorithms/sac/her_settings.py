"""Settings of ``algorithm: her``: the SAC baseline's (copilot_ray.algorithms.sac.settings) plus
hindsight relabelling's ``her.n_sampled_goal`` and ``her.goal_selection``."""

from copilot_ray.algorithms.sac.settings import (
    AGENT,
    GPU_LEARNER,
    HINDSIGHT,
    LEARNER_SEARCH_SPACE,
    METRICS,
    combination_problems,
    max_iteration_env_steps,
)

SETTINGS = {s.key: s for s in (*AGENT, *HINDSIGHT)}
# The shared learner's space plus how many goals are relabelled per real one (SB3's default 4).
SEARCH_SPACE: dict[str, dict] = {**LEARNER_SEARCH_SPACE, "her.n_sampled_goal": {"categorical": [2, 4, 8]}}

__all__ = [
    "GPU_LEARNER",
    "METRICS",
    "SEARCH_SPACE",
    "SETTINGS",
    "combination_problems",
    "max_iteration_env_steps",
]
