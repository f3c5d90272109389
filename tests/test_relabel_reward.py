"""HER's relabelled reward on the learner's device equals the env's own reward under the traversal rules,
env by env and rule by rule."""

import numpy as np
import pytest
import torch

from copilot_ray import envs
from copilot_ray.algorithms.sac.relabel_reward import DeviceRelabelledReward
from copilot_ray.algorithms.sac.traversal_env import TraversalRules

RULES = [
    TraversalRules(),
    TraversalRules(agent_collision="penalty", agent_collision_penalty=0.3, reward_scale=2.0),
    TraversalRules(agent_collision="terminate", agent_collision_penalty=1.0, subtask_reward="uniform"),
]


@pytest.mark.parametrize("env_id", ["maze-point", "maze-rigid", "maze-snake", "ant-maze", "walker-stumps"])
@pytest.mark.parametrize("rules", RULES, ids=["default", "penalty", "terminate"])
def test_the_device_reward_is_the_envs(env_id, rules):
    env = envs.make(env_id).unwrapped
    try:
        rng = np.random.default_rng(0)
        n = 4000
        goals = np.stack([env.goal_space.sample() for _ in range(n)]).astype(np.float32)
        # About half within the success radius, in every dim (angles included, some across +-pi).
        scale = env.success_radius / (np.sqrt(goals.shape[1]) * np.asarray(env.goal_metric.weights))
        noise = rng.normal(0.0, 1.0, goals.shape) * scale
        next_achieved = (goals + noise).astype(np.float32)
        for i in env.goal_metric.angle_dims:
            next_achieved[::3, i] += np.float32(2 * np.pi)
        collisions = rng.random(n) < 0.3
        reached = env.compute_terminated(next_achieved, goals, None)
        reward = env.compute_reward(next_achieved, goals, None)
        want_r, want_t = rules.reward(reward, reached, collisions, layer=0)
        device = DeviceRelabelledReward(env, rules, "cpu")
        got_r, got_t = device(*(torch.as_tensor(x) for x in (next_achieved, goals, collisions)))
        assert 0.2 < np.mean(env.compute_terminated(next_achieved, goals, None)) < 0.8
        np.testing.assert_array_equal(got_t.numpy(), want_t)
        np.testing.assert_allclose(got_r.numpy(), want_r, rtol=0, atol=1e-12)
    finally:
        env.close()
