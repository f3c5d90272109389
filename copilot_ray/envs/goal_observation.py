"""What a goal-conditioned agent sees: its observation and its goal as one flat vector."""

from __future__ import annotations

import gymnasium as gym
import numpy as np


def flat_observation(
    observation: np.ndarray, goal: np.ndarray, achieved: np.ndarray | None = None
) -> np.ndarray:
    """concat(observation, goal), batched or not; with `achieved` (agent_input="state_goal_delta") also
    goal - achieved."""
    parts = [observation, goal] if achieved is None else [observation, goal, goal - achieved]
    return np.concatenate(parts, axis=-1).astype(np.float32)


def flat_observation_space(goal_env: gym.Env, with_delta: bool) -> gym.spaces.Box:
    """The Box of `flat_observation` for a goal-conditioned env (its `observation` space and
    `goal_space`; with_delta: goal - achieved spans goal_space's width either way)."""
    obs_space = goal_env.observation_space["observation"]
    goal_space = goal_env.unwrapped.goal_space
    low, high = [obs_space.low, goal_space.low], [obs_space.high, goal_space.high]
    if with_delta:
        low.append(goal_space.low - goal_space.high)
        high.append(goal_space.high - goal_space.low)
    return gym.spaces.Box(
        np.concatenate(low).astype(np.float32), np.concatenate(high).astype(np.float32), dtype=np.float32
    )
