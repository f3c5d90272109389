"""Every registered env keeps the goal-env contract (copilot_ray/envs/goal_env.py)."""

import numpy as np
import pytest

from copilot_ray import envs
from copilot_ray.envs.goal_env import GoalEnv, GoalMetric, SparseGoalReward, contract_problems


@pytest.mark.parametrize("env_id", envs.env_ids())
def test_every_registered_env_keeps_the_contract(env_id):
    env = envs.make(env_id).unwrapped
    try:
        assert isinstance(env, GoalEnv)
        assert contract_problems(env) == []
    finally:
        env.close()


class _HalfEnv:
    """Declares part of the contract only."""

    goal_dim = 2
    success_radius = 0.1


def test_a_partial_env_is_named_by_what_it_misses():
    problems = contract_problems(_HalfEnv())
    assert not isinstance(_HalfEnv(), GoalEnv)
    assert len(problems) == 1 and "compute_reward" in problems[0] and "tasks" in problems[0]
    assert "success_radius" not in problems[0]


def test_a_reward_that_disagrees_with_termination_is_reported():
    env = envs.make("maze-point", layout="empty").unwrapped
    env.compute_reward = lambda achieved, desired, info=None: np.zeros(np.shape(achieved)[:-1]) + 0.0
    assert any("compute_reward" in p for p in contract_problems(env))


def test_a_goal_metric_that_disagrees_with_goal_distance_is_reported(monkeypatch):
    """HER's device-side reward computes distances from `goal_metric`: a stick whose metric forgets the
    angle's weight and wrap is caught by the contract check."""
    env = envs.make("maze-rigid").unwrapped
    assert env.goal_metric.angle_dims == (2,) and contract_problems(env) == []
    monkeypatch.setattr(type(env), "goal_metric", GoalMetric((1.0, 1.0, 1.0)))
    assert "goal_metric.distance disagrees with goal_distance on validation tasks" in contract_problems(env)


class _Line(SparseGoalReward):
    goal_reward, success_radius = 2.0, 0.5

    def goal_distance(self, a, b):
        return np.abs(np.asarray(a) - np.asarray(b))[..., 0]


def test_sparse_reward_batched_and_single():
    line = _Line()
    achieved, desired = np.array([[0.0], [1.0]]), np.array([[0.4], [0.4]])
    assert line.compute_reward(achieved, desired).tolist() == [2.0, 0.0]
    assert line.compute_terminated(achieved, desired).tolist() == [True, False]
    assert line.compute_reward(np.array([3.0]), np.array([3.4])) == 2.0
    assert line.compute_terminated(np.array([3.0]), np.array([3.6])) is False
