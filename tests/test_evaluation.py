"""follow_waypoints: the step budget per waypoint and for the whole path (SoRB's cap)."""

import numpy as np
import pytest

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


def test_batched_maze_rollouts_equal_env_by_env_rollouts():
    """The maze's lockstep arrays give exactly what N env copies stepped one by one give (collisions,
    sub-goals reached, steps), on four-rooms with a policy that bumps into walls."""
    from copilot_ray import evaluation

    envs = [make("maze-point") for _ in range(30)]
    starts, goals = envs[0].unwrapped.tasks("validation")
    waypoints = np.linspace(starts[:30], goals[:30], 5).transpose(1, 0, 2)

    def wobbly(obs):
        return np.clip((obs[:, 2:4] - obs[:, :2]) / 0.0025, -1, 1) + 0.4 * np.sin(40 * obs[:, :2])

    batched = follow_waypoints(envs, wobbly, waypoints, tau_max=60)
    assert isinstance(evaluation.rollouts_for(envs), evaluation._BatchRollouts)
    one_by_one = evaluation._EnvRollouts(envs)
    original = evaluation.rollouts_for
    evaluation.rollouts_for = lambda _: one_by_one
    try:
        looped = follow_waypoints(envs, wobbly, waypoints, tau_max=60)
    finally:
        evaluation.rollouts_for = original
    assert batched.collided.any() and batched.success.any()  # the comparison covers both
    for field in ("success", "reached_final", "collided", "total_steps", "subtask_steps", "subtask_reached"):
        np.testing.assert_array_equal(getattr(batched, field), getattr(looped, field), err_msg=field)


def test_a_collision_on_an_early_subgoal_fails_the_planned_rollout():
    """The agent bumps into a wall on its way to the first waypoint, then reaches every waypoint:
    reached, but not a success."""
    env = make("maze-point", **OPEN)
    maze = env.unwrapped
    start = np.array([0.03, 0.5])
    # a step straight left from the start would leave the maze (the border is a wall): a collision
    bump_then_go = iter([np.array([[-1.0, 0.0]])])

    def policy(obs):
        first = next(bump_then_go, None)
        return first if first is not None else towards_goal(obs)

    path = np.array([[start, [0.13, 0.5], [0.23, 0.5]]])
    assert maze.is_free(start) and not maze.segments_collide(path[0, :-1], path[0, 1:]).any()
    r = follow_waypoints([env], policy, path, tau_max=10)
    assert r.reached_final.all() and r.collided.all() and not r.success.any()


def test_a_planned_evaluation_never_gets_more_steps_than_the_task():
    """K = 2, tau_max 5: the task's budget is 5 x 2^2 = 20 steps; a planner whose 4 segments each get
    tau_max (a 'scaled' limit would give the finest layer 5) cannot exceed it, even with a generous
    step_limit_of."""
    from copilot_ray.evaluation import evaluate_copilot

    class Straight:
        def sample(self, starts, goals, deterministic=True):
            return np.linspace(starts, goals, 5).transpose(1, 0, 2)

    def stuck(obs):
        return np.zeros((len(obs), 2), np.float32)

    starts = np.array([[0.1, 0.5]], np.float32)
    goals = np.array([[0.9, 0.5]], np.float32)
    common = {"goal_env_id": "maze-point", "goal_env_config": OPEN, "policies": {"d": stuck}}
    result = evaluate_copilot(
        **common,
        planner=Straight(),
        starts=starts,
        goals=goals,
        depth=2,
        tau_max=5,
        step_limit_of=lambda k: 100,  # noqa: ARG005 - more than the task allows
    )
    assert result.by_action["d"]["success_planned"] == 0.0
    from copilot_ray import evaluation

    seen = []
    original = evaluation.follow_waypoints

    def spy(*args, **kwargs):
        out = original(*args, **kwargs)
        seen.append(out.total_steps.max())
        return out

    evaluation.follow_waypoints = spy
    try:
        evaluate_copilot(
            **common,
            planner=Straight(),
            starts=starts,
            goals=goals,
            depth=2,
            tau_max=5,
            step_limit_of=lambda k: 100,  # noqa: ARG005
        )
    finally:
        evaluation.follow_waypoints = original
    assert seen and max(seen) <= 5 * 2**2


def test_per_task_hop_limits_give_a_straight_route_the_whole_budget():
    """SoRB's graph could not route the second task: its single hop gets the task's 100 steps instead of
    a waypoint's 10 (before, it got 10 and failed a 30-step task)."""
    from copilot_ray.algorithms.sorb.algorithm import _GraphWaypoints

    class Graph:
        def waypoints(self, observations, starts, goals):
            routed = np.stack([starts[0], (starts[0] + goals[0]) / 2, goals[0]])
            return [routed, np.stack([starts[1], goals[1]])]

    env = make("maze-point", **OPEN)
    search = _GraphWaypoints(Graph(), env, waypoint_steps=10, total_steps=100)
    starts = np.array([[0.1, 0.5], [0.1, 0.2]], np.float32)
    goals = np.array([[0.5, 0.5], [0.9, 0.2]], np.float32)  # the second is 16 steps away
    waypoints = search.sample(starts, goals)
    limits = search.hop_limits(waypoints)
    np.testing.assert_array_equal(limits, [[10, 10], [10, 100]])
    r = follow_waypoints([make("maze-point", **OPEN) for _ in range(2)], towards_goal, waypoints, limits)
    assert r.success.all() and r.total_steps[1] > 10


def test_the_evaluation_cadence_counts_env_steps_not_iterations():
    from copilot_ray.evaluation import EvaluationSchedule

    every_10k = EvaluationSchedule(every_iterations=1, every_env_steps=10_000)
    # iterations of different sizes: evaluated once per 10k boundary passed, whatever the iteration count
    ends = [4_000, 9_999, 10_500, 16_000, 31_000, 33_000, 40_000]
    assert [every_10k.due(i + 1, s) for i, s in enumerate(ends)] == [
        False,
        False,
        True,
        False,
        True,
        False,
        True,
    ]
    restored = EvaluationSchedule(1, 10_000)
    restored.set_state(every_10k.get_state())
    assert not restored.due(8, 45_000) and restored.due(9, 50_000)
    every_2 = EvaluationSchedule(every_iterations=2)
    assert [every_2.due(i, 0) for i in range(1, 5)] == [False, True, False, True]


def test_success_auc_is_the_normalised_area_under_the_evaluations():
    from copilot_ray.evaluation import SuccessCurve

    curve = SuccessCurve()
    assert curve.add(10_000, 0.2) == 0.2  # one evaluation: its value
    assert curve.add(20_000, 0.4) == pytest.approx(0.3)
    assert curve.add(40_000, 0.4) == pytest.approx((0.3 * 10_000 + 0.4 * 20_000) / 30_000)
