"""The classical-planner curriculum: RRT* paths cut into sub-goal trees, and CO-PILOT's agent on them."""

import numpy as np
import pytest

from copilot_ray.envs import make
from copilot_ray.planning.rrt_trees import RRTTrees, cut_path
from copilot_ray.planning.subgoal_tree import layer_indices


def euclid(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b), axis=-1)


def test_a_path_is_cut_into_pieces_of_equal_length_from_its_start_to_its_end():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [1.0, 0.5], [1.0, 1.0]])  # a repeated point too
    points = cut_path(path, 8, euclid)
    np.testing.assert_allclose(points[0], path[0])
    np.testing.assert_allclose(points[-1], path[-1])
    np.testing.assert_allclose(euclid(points[1:], points[:-1]), 0.25, atol=1e-12)  # 2 / 8, no corner cut
    np.testing.assert_allclose(points[4], [1.0, 0.0])  # halfway along is the corner
    # A one-point path (start at the goal) is that point repeated.
    np.testing.assert_array_equal(cut_path(path[:1], 4, euclid), np.zeros((5, 2)))


def test_angles_are_interpolated_the_short_way_round():
    path = np.array([[0.0, 3.0], [0.0, -3.0]])  # the angle moves 2 pi - 6 ~ 0.28, not 6

    def distance(a, b):
        return np.abs((np.asarray(b)[..., 1] - np.asarray(a)[..., 1] + np.pi) % (2 * np.pi) - np.pi)

    mid = cut_path(path, 2, distance, angle_dims=(1,))[1]
    assert abs(mid[1] - (3.0 + (2 * np.pi - 6.0) / 2)) < 1e-9


def test_bad_paths_are_refused():
    with pytest.raises(ValueError, match="pieces must be >= 1"):
        cut_path(np.zeros((2, 2)), 0, euclid)
    with pytest.raises(ValueError, match=r"a path is \[P >= 1, d\] points"):
        cut_path(np.zeros((0, 2)), 2, euclid)


def test_rrt_trees_run_from_start_to_goal_their_layers_are_the_path_cut_evenly_and_each_task_is_planned_once():
    env = make("maze-point", layout="four-rooms")
    maze = env.unwrapped
    starts, goals = maze.tasks("validation")
    trees = RRTTrees(env, depth=3, time_limit_s=0.1, seed=0)
    planned, plan = [], trees._rrt.plan

    def recorded(*args, **kwargs):  # the paths RRT* returns (their shape varies with its time budget)
        result = plan(*args, **kwargs)
        planned.append(result)
        return result

    trees._rrt.plan = recorded
    out = trees.sample(starts[:3], goals[:3])
    assert out.shape == (3, 9, 2) and out.dtype == np.float32
    np.testing.assert_allclose(out[:, 0], starts[:3])
    np.testing.assert_allclose(out[:, -1], goals[:3])
    solved = trees.solved
    assert solved + trees.unsolved == 3 and trees.checks > 0
    assert len(planned) == 3
    for task, result in enumerate(planned):
        if result.solved:  # the tree is the path (on to the goal itself) cut into 8 equal lengths
            path = np.concatenate([result.path, goals[task][None]])
            np.testing.assert_allclose(out[task], cut_path(path, 8, maze.goal_distance), atol=1e-5)
        else:  # no path: the straight segment, cut evenly
            np.testing.assert_allclose(
                euclid(out[task, 1:], out[task, :-1]), euclid(starts[task], goals[task]) / 8, atol=1e-5
            )
        layer1 = out[task, layer_indices(3, 1)]
        assert layer1.shape == (3, 2)
    checks = trees.checks
    again = trees.sample(starts[:3][::-1], goals[:3][::-1])
    np.testing.assert_array_equal(again, out[::-1])
    assert trees.checks == checks  # kept, not planned again

    restored = RRTTrees(env, depth=3, time_limit_s=0.1, seed=0)
    restored.load_state_dict(trees.state_dict())
    np.testing.assert_array_equal(restored.sample(starts[:3], goals[:3]), out)
    assert (restored.checks, restored.solved, restored.unsolved) == (checks, trees.solved, trees.unsolved)


def test_the_curriculums_test_budget_is_the_same_whatever_its_depth():
    from copilot_ray.algorithms.rrt_curriculum.settings import TASK_STEPS, max_iteration_env_steps, tau_max_of

    assert TASK_STEPS == 800
    assert {k: tau_max_of({"tree_depth": k}) * 2**k for k in (3, 4, 5)} == {3: 800, 4: 800, 5: 800}
    assert tau_max_of({"tree_depth": 5, "tau_max": 10}) == 10
    # CO-PILOT's bound at K = 5, b = 5, 2 tasks: 2 x 5 x 63 sub-tasks x 25 steps.
    assert max_iteration_env_steps({}) == 2 * 5 * 63 * 25


@pytest.mark.ray
def test_an_iteration_traverses_rrt_trees_counts_every_check_and_a_restore_plans_nothing_again(ray_session):
    """Training trees, then validation and test trees at the evaluation: every RRT* check lands in the
    privilege count the iteration logs (after its evaluation), and a restored run keeps the trees."""
    from copilot_ray.registry import RunContext, get_algorithm

    entry = get_algorithm("rrt_curriculum")
    assert entry.privileges(entry.defaults_as_logged()) == ("collision_checks",)
    values = {
        "tree_depth": 2,
        "repetitions": 1,
        "eval_num_tasks": 3,
        "curriculum.rrt_time_s": 0.05,
        "num_steps_sampled_before_learning_starts": 10_000,  # wiring only: no SAC update
    }
    run = RunContext("maze-point", {"layout": "u-maze"}, seed=2)
    algo = entry.build_config(values, run).build_algo()
    try:
        assert algo.config.tau_max == 800 // 4
        result = algo.train()
        trees = algo.curriculum.planner
        assert trees.solved + trees.unsolved == 2 + 3 + 3  # 2 training tasks, 3 validation, 3 test
        assert result["copilot"]["privileges"]["collision_checks"] == trees.checks > 0
        assert result["copilot"]["curriculum"]["rrt_tasks"] == 8
        state = algo.get_state()
    finally:
        algo.stop()
    restored = entry.build_config(values, run).build_algo()
    try:
        restored.set_state(state)
        checks = restored.curriculum.planner.checks
        restored._evaluate()  # the same evaluation tasks: their trees are kept
        assert restored.curriculum.planner.checks == checks == trees.checks
    finally:
        restored.stop()
