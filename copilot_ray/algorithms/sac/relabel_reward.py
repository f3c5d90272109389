"""What a relabelled transition earns: HER's reward for a new goal, on the learner's device.

`DeviceRelabelledReward` is the goal env's sparse reward and termination (`compute_reward`,
`compute_terminated`) under the traversal rules the env runners apply (one sub-task = one task: layer
0), on torch tensors of the learner's device, with no host synchronisation, for `HindsightReplayBuffer`.
It reads the env's distance as data (`goal_metric`, held equal to `goal_distance` by the env contract)
and computes in float64, as the env does.
"""

from __future__ import annotations

import math

import torch

from copilot_ray.algorithms.sac.traversal_env import TraversalRules


class DeviceRelabelledReward:
    """HER's relabelled reward on device tensors: a `gc_sac.TorchRewardFn` for `HindsightReplayBuffer`."""

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
