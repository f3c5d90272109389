"""TraversalEnv: one RLlib episode = one sub-task of CO-PILOT's bottom-up traversal (Algorithm 2).

The driver loads sub-goal trees into the env (`load_plan`); every `reset` pops the next sub-task:
for each task, layers k = K..0 in order, the 2^k sub-goals of layer k left to right. The first sub-task
of a layer starts from the task's s0, every other one from wherever the agent stopped. An episode
terminates when the agent reaches its sub-goal (reward R / 2^k) and is truncated after `tau_max` steps.
Because a sub-task is an ordinary episode, SAC's episodes, buffers and learners are reused unchanged,
and the D_tau tuple of a sub-task is read off the last `info` of its episode - no side channel.

Where the paper is silent or its literal reading starves the agent, `TraversalRules` holds the choice
(each a CoPilotConfig knob; the paper's reading first):

* `step_limit`: "fixed" (tau_max for every sub-task, the paper) or "scaled" (tau_max * 2^(K-k) for
  layer k, whose segments span 2^(K-k) finest ones).
* `after_failure`: "continue" (the next sub-task starts where the agent stopped, the paper), "restart"
  (it starts at the missed sub-goal when the map says that is free space, so one failure does not fail
  the rest of the layer: a privilege no baseline has, a reset to a state other than a task's start and a
  map query, both counted in the sub-task's last info) or "abort_layer" (the rest of the layer is
  dropped: no env steps spent on a cascade; the next layer starts at the task's start, as every
  baseline's episodes do).
* `subtask_reward`: "halving" (R / 2^k, Eq. 6) or "uniform" (R for every sub-task); `reward_scale`
  multiplies R, the goal env's reward.
* `agent_collision`: "none" (a blocked move costs nothing, the paper), "penalty" (reward
  -collision_penalty for each blocked move) or "terminate" (the episode ends there with that penalty).
* `agent_input`: the observation is concat(observation, sub-goal) ("state_goal", the paper's
  pi(a | s, g)) or that plus sub-goal - achieved goal ("state_goal_delta").

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

from copilot_ray.algorithms.sac.settings import SETTINGS, TREE_TRAVERSAL
from copilot_ray.algorithms.sac.traversal_channel import subtask_info
from copilot_ray.envs import make
from copilot_ray.envs.continuation import reset_toward
from copilot_ray.envs.goal_observation import flat_observation, flat_observation_space
from copilot_ray.planning.subgoal_tree import path_indices
from copilot_ray.settings import record_class

TRAVERSAL_ENV_ID = "copilot-traversal"


# The settings that say how sub-tasks are run and rewarded (the env runners get them in env_config).
RULE_KEYS = (
    "tau_max",
    "train_episode_steps",
    "step_limit",
    "after_failure",
    "subtask_reward",
    "reward_scale",
    "agent_collision",
    "agent_collision_penalty",
    "agent_input",
)


_RULES = {**SETTINGS, **{s.key: s for s in TREE_TRAVERSAL}}


class TraversalRules(record_class("TraversalRules", {k: _RULES[k] for k in RULE_KEYS}, with_run=False)):
    """How sub-tasks are run and rewarded (see the module docstring): the settings of the same names,
    their defaults and rules read off settings.py, checked on construction."""

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> TraversalRules:
        """The rules from a traversal env_config (keys of this class; missing ones keep their defaults)."""
        return cls(**{k: config[k] for k in cls.__dataclass_fields__ if k in config})

    def training_step_limit_of(self, layer: int, depth: int) -> int:
        """Steps a layer-`layer` sub-task may take in training: `train_episode_steps` where set (the
        agent alone's episodes), else as in evaluation (`step_limit_of`)."""
        if self.train_episode_steps is not None:
            return int(self.train_episode_steps)
        return self.step_limit_of(layer, depth)

    def step_limit_of(self, layer: int, depth: int) -> int:
        """Steps a layer-`layer` sub-task of a depth-`depth` tree may take."""
        if self.step_limit == "scaled":
            return self.tau_max * 2 ** max(depth - layer, 0)
        return self.tau_max

    def reward_factor(self, layer: int) -> float:
        """What the goal env's reward R is multiplied by in layer `layer`: 1 / 2^k (Eq. 6) or 1."""
        if self.subtask_reward == "halving":
            return self.reward_scale / 2**layer
        return self.reward_scale

    def reward(
        self,
        env_reward: np.ndarray,
        reached: np.ndarray,
        collision: np.ndarray,
        layer: int = 0,
        dense: np.ndarray | float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(reward, terminated) of transitions, batched: the goal env's reward times `reward_factor`,
        minus the collision penalty, plus the env's goal-independent `dense` reward as it is
        (info["dense_reward"]: the walker's own reward; 0 elsewhere); terminated on reaching the
        sub-goal (or colliding, with agent_collision="terminate"). TraversalEnv.step and HER's
        relabelled rewards both use it."""
        reward = np.asarray(env_reward, np.float64) * self.reward_factor(layer) + np.asarray(
            dense, np.float64
        )
        terminated = np.asarray(reached, bool)
        if self.agent_collision != "none":
            collision = np.asarray(collision, bool)
            reward = reward - self.agent_collision_penalty * collision
            if self.agent_collision == "terminate":
                terminated = terminated | collision
        return reward, terminated


@dataclass(frozen=True)
class SubTask:
    task_id: int
    layer: int
    index: int  # 1..2^layer along the layer's path
    goal: np.ndarray
    start: np.ndarray | None  # s0 for the first sub-task of a layer, else None: continue in place


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

        self.goal_env = make(config["goal_env"], **dict(config.get("goal_env_config") or {}))
        self.inner = self.goal_env.unwrapped
        self.rules = TraversalRules.from_config(config)
        self.tau_max = self.rules.tau_max
        self._with_delta = self.rules.agent_input == "state_goal_delta"
        self.observation_space = flat_observation_space(self.goal_env, self._with_delta)
        self.action_space = self.goal_env.action_space
        self._queue: deque[SubTask] = deque()
        self._current: SubTask | None = None
        self._position: np.ndarray | None = None  # the agent's configuration (goal space)
        self._start: np.ndarray | None = None
        self._steps = 0
        self._limit = self.tau_max
        self._depth = 0
        self._missed: np.ndarray | None = None  # the sub-goal the last sub-task failed to reach
        self._idle_goal: np.ndarray | None = None
        # Privileges this sub-task's start used (copilot_ray.privileges): a map query, and a reset of
        # the agent to the missed sub-goal (after_failure="restart"); reported at its end.
        self._map_queries = 0
        self._reset_to_state = False

    # --- driver-facing -------------------------------------------------------------------------
    def load_plan(self, trees: np.ndarray, depth: int, task_ids: np.ndarray) -> int:
        """Replaces the queue with the traversal of `trees`; returns the number of sub-tasks."""
        self._queue = deque(traversal_queue(np.asarray(trees), int(depth), np.asarray(task_ids)))
        self._depth = int(depth)
        self._missed = None
        return len(self._queue)

    def remaining(self) -> int:
        return len(self._queue)

    # --- gymnasium -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._map_queries, self._reset_to_state = 0, False
        if self._queue:
            self._current = self._queue.popleft()
            start, carry_on = self._current.start, False
            if start is None:
                start, carry_on = self._continue_from()
            goal = self._current.goal
            self._limit = self.rules.training_step_limit_of(self._current.layer, self._depth)
            self._idle_goal = None
        else:
            # Nothing planned (RLlib resets envs at construction, and may sample before a plan is
            # loaded): a harmless placeholder episode that the driver recognises and drops.
            self._current = None
            tasks = self.inner.tasks("train")
            carry_on = self._position is not None
            start = self._position if carry_on else tasks[0][0]
            goal = tasks[1][0]
            self._limit = self.tau_max
            self._idle_goal = goal
        if carry_on:  # from where the agent stands (an Ant keeps its motion)
            obs, info = reset_toward(self.goal_env, start, goal)
        else:
            obs, info = self.goal_env.reset(options={"start": np.asarray(start), "goal": np.asarray(goal)})
        self._position = obs["achieved_goal"].copy()
        self._start = self._position.copy()
        self._steps = 0
        return self._flat(obs), {"achieved_goal": self._position.copy()}

    def _flat(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        achieved = obs["achieved_goal"] if self._with_delta else None
        return flat_observation(obs["observation"], obs["desired_goal"], achieved)

    def _continue_from(self) -> tuple[np.ndarray, bool]:
        """Where a sub-task that is not the first of its layer starts (see `after_failure`), and whether
        that is carrying on from where the agent stands."""
        missed, self._missed = self._missed, None
        if missed is not None and self.rules.after_failure == "restart" and self._is_free(missed):
            self._reset_to_state = True
            return missed, False
        return self._position, True

    def _is_free(self, config: np.ndarray) -> bool:
        """Asks the map (a privilege, counted)."""
        clearance = getattr(self.inner, "is_free", None)
        if clearance is None:
            return True
        self._map_queries += 1
        return bool(clearance(config))

    def _drop_rest_of_layer(self) -> None:
        cur = self._current
        while self._queue and self._queue[0].task_id == cur.task_id and self._queue[0].layer == cur.layer:
            if self._queue[0].start is not None:  # the same layer of the next repetition of this task
                break
            self._queue.popleft()

    def step(self, action):
        return self._after_goal_step(*self.goal_env.step(action))

    def step_to(self, config: np.ndarray, collision: bool):
        """`step` with the goal env's motion given (`GoalMazeEnv.step_to`: a seed stack moves every
        seed's agent in one `batch_step`)."""
        return self._after_goal_step(*self.inner.step_to(config, collision))

    def _after_goal_step(self, obs, reward, reached, _truncated, info):
        self._steps += 1
        self._position = obs["achieved_goal"].copy()
        layer = self._current.layer if self._current is not None else 0
        collision = bool(info.get("collision", False))
        # Sub-task reward (paper Eq. 6: R / 2^k, so every layer's traversal is worth R in total).
        dense = float(info.get("dense_reward", 0.0))
        reward, terminated = self.rules.reward(reward, reached, collision, layer, dense)
        reward, terminated = float(reward), bool(terminated)
        # A failure the agent cannot undo (the Ant flipped over) ends the sub-task early.
        failed = bool(info.get("failed", False))
        truncated = (not terminated) and (self._steps >= self._limit or failed)
        # The achieved goal of every step: what hindsight relabelling (HER, SoRB) takes goals from.
        out_info = {"collision": collision, "achieved_goal": self._position, "dense_reward": dense}
        if terminated or truncated:
            out_info.update(
                subtask_info(
                    idle=self._current is None,
                    task=-1 if self._current is None else self._current.task_id,
                    layer=layer,
                    index=0 if self._current is None else self._current.index,
                    start=self._start.copy(),
                    end=self._position.copy(),
                    goal=np.asarray(obs["desired_goal"], np.float32).copy(),
                    steps=self._steps,
                    reached=bool(reached),
                    collided=collision and not reached,
                    reset_to_state=self._reset_to_state,
                    map_queries=self._map_queries,
                )
            )
            if not reached and self._current is not None:
                self._missed = self._current.goal.copy()
                if self.rules.after_failure == "abort_layer":
                    self._drop_rest_of_layer()
        return (
            self._flat(obs),
            reward,
            terminated,
            bool(truncated),
            out_info,
        )


def make_traversal_env(config: Mapping[str, Any]) -> TraversalEnv:
    return TraversalEnv(config)
