"""follow_waypoints: the step budget per waypoint and for the whole path (SoRB's cap)."""

import numpy as np

from copilot_ray.envs import make
from copilot_ray.evaluation import follow_waypoints

OPEN = {"layout": "empty", "speed": 0.05, "success_radius": 0.01}


def towards_goal(obs):
    """A perfect policy for the point mass with agent_input="state_goal": unit steps to the goal."""
    position, goal = obs[:, :2], obs[:, 2:4]
    delta = goal - position
    return np.clip(delta / 0.05, -1.0, 1.0)


def test_waypoints_are_followed_and_the_total_budget_cuts_the_path():
    envs = [make("maze-point", **OPEN) for _ in range(2)]
    # 0.1 between waypoints: 2 steps each; four hops in all
    path = np.array([[0.1, 0.5], [0.2, 0.5], [0.3, 0.5], [0.4, 0.5], [0.5, 0.5]])
    waypoints = np.stack([path, path])
    full = follow_waypoints(envs, towards_goal, waypoints, tau_max=10)
    assert full.success.all() and (full.total_steps == 8).all()
    np.testing.assert_array_equal(full.subtask_steps, [[2, 2, 2, 2]] * 2)
    cut = follow_waypoints(envs, towards_goal, waypoints, tau_max=10, max_total_steps=5)
    assert not cut.reached_final.any() and (cut.total_steps == 5).all()
    np.testing.assert_array_equal(cut.subtask_reached, [[True, True, False, False]] * 2)
    # a waypoint out of reach within tau_max is given up, the next one is tried from where it stopped
    far = np.array([[[0.1, 0.5], [0.9, 0.5], [0.9, 0.6]]])
    r = follow_waypoints(envs[:1], towards_goal, far, tau_max=5)
    np.testing.assert_array_equal(r.subtask_reached, [[False, False]])
    assert r.total_steps[0] == 10
