"""Settings of ``algorithm: her``: the SAC baseline's (copilot_ray.algorithms.sac.settings) plus
hindsight relabelling's ``her.n_sampled_goal`` and ``her.goal_selection``."""

from copilot_ray.algorithms.sac.settings import (
    AGENT,
    GPU_LEARNER,
    HINDSIGHT,
    LEARNER_SEARCH_SPACE,
    METRICS,
    SEED_STACK,
    combination_problems,
    max_iteration_env_steps,
)

SETTINGS = {s.key: s for s in (*AGENT, *HINDSIGHT)}
# The shared learner's space (gamma up to 0.995), how many goals are relabelled per real one (SB3's default
# 4), and the training episodes' length (null: tau_max, 800 on four-rooms; test tasks keep tau_max steps).
SEARCH_SPACE: dict[str, dict] = {
    **LEARNER_SEARCH_SPACE,
    "her.n_sampled_goal": {"categorical": [2, 4, 8]},
    "train_episode_steps": {"categorical": [None, 100, 200, 400]},
}

__all__ = [
    "GPU_LEARNER",
    "SEED_STACK",
    "METRICS",
    "SEARCH_SPACE",
    "SETTINGS",
    "combination_problems",
    "max_iteration_env_steps",
]
