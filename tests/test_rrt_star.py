"""RRT* through OMPL on the maze envs' own checks: it solves, its paths are free, it counts checks."""

from __future__ import annotations

import numpy as np
import pytest

from copilot_ray.envs import make
from copilot_ray.envs.maze import shortest_path_lengths
from copilot_ray.planning.rrt_star import _groups, rrt_star_for_env


def test_subspaces_follow_the_dims_angles_and_weights():
    assert _groups([1.0, 1.0], []) == [("vector", [0, 1], 1.0)]
    assert _groups([1.0, 1.0, 0.025], [2]) == [("vector", [0, 1], 1.0), ("angle", [2], 0.025)]
    assert _groups([1.0, 1.0, 0.06, 0.04, 0.02], [2]) == [
        ("vector", [0, 1], 1.0),
        ("angle", [2], 0.06),
        ("vector", [3], 0.04),
        ("vector", [4], 0.02),
    ]


@pytest.mark.parametrize("agent", ["point", "rigid", "snake"])
def test_rrt_star_solves_test_tasks_with_collision_free_paths(agent):
    env = make(f"maze-{agent}", layout="u-maze")
    maze = env.unwrapped
    starts, goals = (x.astype(np.float64)[:3] for x in maze.tasks("test"))
    rrt = rrt_star_for_env(env, time_limit_s=1.0)  # wall time: RRT* is time-bound, so its sample count varies
    for start, goal in zip(starts, goals, strict=True):
        result = rrt.plan(start, goal, maze.success_radius)
        assert result.solved, (agent, start, goal)
        path = result.path
        np.testing.assert_allclose(path[0], start, atol=1e-9)
        assert maze.goal_distance(path[-1], goal) <= maze.success_radius + 1e-9
        assert not maze.segments_collide(path[:-1], path[1:]).any()  # the env's own motion check agrees
        assert result.state_checks > 0 and result.motion_checks > 0
        if agent == "point":
            shortest = shortest_path_lengths(env, start[None], goal[None])[0]
            # it may stop up to the success radius short of the goal
            assert shortest - maze.success_radius - 1e-9 <= result.length < 3 * shortest


def test_an_unreachable_goal_is_not_solved():
    env = make("maze-point", layout="u-maze")
    rrt = rrt_star_for_env(env, time_limit_s=0.1)
    # The goal lies inside a wall: no valid path ends within the radius of it.
    wall = np.argwhere(env.unwrapped.layout.grid)[0]
    rows, cols = env.unwrapped.layout.shape
    goal = np.array([(wall[1] + 0.5) / cols, 1.0 - (wall[0] + 0.5) / rows])
    start = env.unwrapped.tasks("test")[0][0].astype(np.float64)
    result = rrt.plan(start, goal, 1e-3)
    assert not result.solved and result.length == float("inf") and len(result.path) == 0


def test_a_start_in_an_obstacle_is_refused_naming_it():
    env = make("maze-rigid", layout="four-rooms")
    rrt = rrt_star_for_env(env, time_limit_s=0.05)
    with pytest.raises(ValueError, match=r"start \[0.5, 0.5, 0.0\] lies in an obstacle"):
        rrt.plan(np.array([0.5, 0.5, 0.0]), np.array([0.1, 0.1, 0.0]), 0.025)
    env.close()
