"""What a relabelled transition earns: HER's reward for a new goal, on the host and on the learner's
device.

`relabelled_reward` is the goal env's sparse reward and termination under the traversal rules the env
runners apply (one sub-task = one task: layer 0), as numpy; `DeviceRelabelledReward` is the same on
torch tensors of the learner's device, with no host synchronisation, for `DeviceHindsightBuffer`. It
reads the env's distance as data (`goal_metric`, held equal to `goal_distance` by the env contract)
and computes in float64, as the numpy one does.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from copilot_ray.algorithms.sac.traversal_env import TraversalRules


def relabelled_reward(
    env, rules: TraversalRules, next_achieved: np.ndarray, goals: np.ndarray, collisions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(rewards, terminateds) of transitions given new goals, for the (unwrapped) goal env `env`."""
    reached = env.compute_terminated(next_achieved, goals, None)
    return rules.reward(env.compute_reward(next_achieved, goals, None), reached, collisions, layer=0)


class DeviceRelabelledReward:
    """`relabelled_reward` on device tensors: a `gc_sac.TorchRewardFn` for `DeviceHindsightBuffer`."""

    def __init__(self, env, rules: TraversalRules, device: torch.device | str):
        metric = env.goal_metric
        self.device = torch.device(device)
        self.weights = torch.as_tensor(metric.weights, dtype=torch.float64, device=self.device)
        self.angle_dims = tuple(metric.angle_dims)
        # Made here, not per call: no host-to-device copy inside a captured step.
        self._angle_index = torch.as_tensor(self.angle_dims, dtype=torch.int64, device=self.device)
        self.success_radius = float(env.success_radius)
        self.goal_reward = float(env.goal_reward)
        self.rules = rules

    def __call__(
        self, next_achieved: torch.Tensor, goals: torch.Tensor, collisions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        d = goals.double() - next_achieved.double()
        if self.angle_dims:
            wrapped = torch.remainder(d.index_select(1, self._angle_index) + math.pi, 2 * math.pi) - math.pi
            d = d.index_copy(1, self._angle_index, wrapped)
        reached = torch.sqrt(((self.weights * d) ** 2).sum(-1)) <= self.success_radius
        reward = reached.double() * (self.goal_reward * self.rules.reward_factor(0))
        terminated = reached
        if self.rules.agent_collision != "none":
            reward = reward - self.rules.agent_collision_penalty * collisions.double()
            if self.rules.agent_collision == "terminate":
                terminated = terminated | collisions.bool()
        return reward, terminated
