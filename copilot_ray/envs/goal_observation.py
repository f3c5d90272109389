"""What a goal-conditioned agent sees: its observation and its goal as one flat vector."""

from __future__ import annotations

import numpy as np


def flat_observation(
    observation: np.ndarray, goal: np.ndarray, achieved: np.ndarray | None = None
) -> np.ndarray:
    """concat(observation, goal), batched or not; with `achieved` (agent_input="state_goal_delta") also
    goal - achieved."""
    parts = [observation, goal] if achieved is None else [observation, goal, goal - achieved]
    return np.concatenate(parts, axis=-1).astype(np.float32)
