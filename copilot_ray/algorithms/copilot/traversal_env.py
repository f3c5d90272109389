"""TraversalEnv: one RLlib episode = one sub-task of CO-PILOT's bottom-up traversal (Algorithm 2).

The driver loads sub-goal trees into the env (`load_plan`); every `reset` pops the next sub-task:
for each task, layers k = K..0 in order, the 2^k sub-goals of layer k left to right. The first sub-task
of a layer starts from the task's s0, every other one from wherever the agent stopped (a failed
sub-task leaves the agent where it is). An episode terminates when the agent reaches its sub-goal
(reward R / 2^k) and is truncated after `tau_max` steps. Because a sub-task is an ordinary episode,
SAC's episodes, buffers and learners are reused unchanged, and the D_tau tuple of a sub-task is read
off the last `info` of its episode - no side channel.

The agent is conditioned on the current sub-goal: the observation is the flat vector
concat(observation, sub-goal), which `flat_observation` also builds for evaluation.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from copilot_ray.planning.subgoal_tree import layer_indices

TRAVERSAL_ENV_ID = "copilot-traversal"


def flat_observation(observation: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The goal-conditioned agent's input: concat(observation, goal), batched or not."""
    return np.concatenate([observation, goal], axis=-1).astype(np.float32)


@dataclass(frozen=True)
class SubTask:
    task_id: int
    layer: int
    index: int  # 1..2^layer along the layer's path
    goal: np.ndarray
    start: np.ndarray | None  # s0 for the first sub-task of a layer, else None: continue in place


def path_indices(depth: int, k: int) -> np.ndarray:
    """Indices of layer k's path in a tree; depth 0 (no planner: [s0, g]) has only layer 0."""
    return np.array([0, 1]) if depth == 0 else layer_indices(depth, k)


def traversal_queue(trees: np.ndarray, depth: int, task_ids: np.ndarray) -> list[SubTask]:
    """Sub-tasks of the bottom-up traversal of every tree, task by task, layers K..0."""
    queue = []
    for tree, task_id in zip(trees, task_ids, strict=True):
        for k in range(depth, -1, -1):
            path = tree[path_indices(depth, k)]
            for t in range(1, len(path)):
                start = path[0] if t == 1 else None
                queue.append(SubTask(int(task_id), k, t, path[t].copy(), start))
    return queue


class TraversalEnv(gym.Env):
    """Wraps a goal-conditioned env (copilot_ray.envs) so that each episode is one planned sub-task."""

    metadata = {"render_modes": []}

    def __init__(self, config: Mapping[str, Any]):
        from copilot_ray.envs import make

        self.goal_env = make(config["goal_env"], **dict(config.get("goal_env_config") or {}))
        self.inner = self.goal_env.unwrapped
        self.tau_max = int(config["tau_max"])
        obs_space = self.goal_env.observation_space["observation"]
        goal_space = self.inner.goal_space
        self.observation_space = gym.spaces.Box(
            low=np.concatenate([obs_space.low, goal_space.low]).astype(np.float32),
            high=np.concatenate([obs_space.high, goal_space.high]).astype(np.float32),
            dtype=np.float32,
        )
        self.action_space = self.goal_env.action_space
        self._queue: deque[SubTask] = deque()
        self._current: SubTask | None = None
        self._position: np.ndarray | None = None  # the agent's configuration (goal space)
        self._start: np.ndarray | None = None
        self._steps = 0
        self._idle_goal: np.ndarray | None = None

    # --- driver-facing -------------------------------------------------------------------------
    def load_plan(self, trees: np.ndarray, depth: int, task_ids: np.ndarray) -> int:
        """Replaces the queue with the traversal of `trees`; returns the number of sub-tasks."""
        self._queue = deque(traversal_queue(np.asarray(trees), int(depth), np.asarray(task_ids)))
        return len(self._queue)

    def remaining(self) -> int:
        return len(self._queue)

    # --- gymnasium -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if self._queue:
            self._current = self._queue.popleft()
            start = self._current.start if self._current.start is not None else self._position
            goal = self._current.goal
            self._idle_goal = None
        else:
            # Nothing planned (RLlib resets envs at construction, and may sample before a plan is
            # loaded): a harmless placeholder episode that the driver recognises and drops.
            self._current = None
            tasks = self.inner.tasks("train")
            start = self._position if self._position is not None else tasks[0][0]
            goal = tasks[1][0]
            self._idle_goal = goal
        obs, info = self.goal_env.reset(options={"start": np.asarray(start), "goal": np.asarray(goal)})
        self._position = obs["achieved_goal"].copy()
        self._start = self._position.copy()
        self._steps = 0
        return flat_observation(obs["observation"], obs["desired_goal"]), {}

    def step(self, action):
        obs, reward, reached, _, info = self.goal_env.step(action)
        self._steps += 1
        self._position = obs["achieved_goal"].copy()
        layer = self._current.layer if self._current is not None else 0
        truncated = (not reached) and self._steps >= self.tau_max
        out_info = {"collision": bool(info.get("collision", False))}
        if reached or truncated:
            out_info.update(
                subtask_idle=self._current is None,
                subtask_task=-1 if self._current is None else self._current.task_id,
                subtask_layer=layer,
                subtask_index=0 if self._current is None else self._current.index,
                subtask_start=self._start.copy(),
                subtask_end=self._position.copy(),
                subtask_steps=self._steps,
                subtask_reached=bool(reached),
            )
        # Sub-task reward R / 2^k (paper Eq. 6): every layer's traversal is worth R in total.
        reward = float(reward) / float(2**layer)
        return (
            flat_observation(obs["observation"], obs["desired_goal"]),
            reward,
            bool(reached),
            bool(truncated),
            out_info,
        )


def make_traversal_env(config: Mapping[str, Any]) -> TraversalEnv:
    return TraversalEnv(config)
