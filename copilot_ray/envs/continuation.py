"""Moving on to the next sub-goal: the one place that knows how a goal env continues an episode."""

from __future__ import annotations

from typing import Any

import numpy as np


def reset_toward(env: Any, position: np.ndarray, goal: np.ndarray):
    """Reset `env` for the next sub-goal from where the agent stands.

    An env whose state is more than its goal-space position (the Ant's joints and velocities) declares
    `goal_only_reset = True`: it keeps its physical state and only takes the new goal. Others (the 1 x 1
    maze, where the position is the whole state) are placed at `position` afresh, which is the same."""
    if getattr(env.unwrapped, "goal_only_reset", False):
        return env.reset(options={"goal": np.asarray(goal)})
    return env.reset(options={"start": np.asarray(position), "goal": np.asarray(goal)})
