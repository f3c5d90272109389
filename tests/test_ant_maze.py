"""The MuJoCo Ant maze: tasks, the planner's wall geometry, contacts and flips, continuing a motion
across sub-goals, bad input, and the off-screen frame."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from copilot_ray.envs import make

# U-maze (cells of 4 m, map 5 x 5 centred on 0): corridors y in (2, 6) and (-6, -2) joined at x in (2, 6);
# the middle wall spans x in (-6, 2), y in (-2, 2).
UPPER, LOWER = np.array([-4.0, 4.0]), np.array([-4.0, -4.0])


@pytest.fixture(scope="module")
def env():
    e = make("ant-maze")
    yield e
    e.close()


def test_task_sets_are_seeded_free_apart_and_disjoint(env):
    starts, goals = env.tasks("train")
    test_starts, test_goals = env.tasks("test")
    assert starts.shape == goals.shape == (50, 2) and test_starts.shape == (10, 2)  # the paper's 50 / 10
    assert all(env.is_free(p) for p in np.concatenate([starts, goals, test_starts, test_goals]))
    assert (env.goal_distance(starts, goals) >= 4.0).all()
    assert not {tuple(r) for r in np.hstack([starts, goals]).tolist()} & {
        tuple(r) for r in np.hstack([test_starts, test_goals]).tolist()
    }
    again = make("ant-maze")
    np.testing.assert_array_equal(again.tasks("train")[0], starts)
    other = make("ant-maze", task_seed=1)
    assert not np.array_equal(other.tasks("train")[0], starts)
    again.close(), other.close()


def test_planner_geometry_is_the_walls_grown_by_the_margin(env):
    a = np.array([UPPER, UPPER, [4.0, 4.0], [-4.0, 2.3]])
    b = np.array([LOWER, [4.0, 4.0], [4.0, -4.0], [0.0, 2.3]])
    # through the middle wall; along the upper corridor; down the right corridor; 0.3 m from the wall
    np.testing.assert_array_equal(env.segments_collide(a, b), [True, False, False, True])
    lengths = env.collision_lengths(a, b)
    assert lengths[0] == pytest.approx(4.0 + 2 * 0.5)  # the 4 m wall plus the margin on both sides
    assert lengths[1] == lengths[2] == 0.0
    # margin 0: the same segment 0.3 m from the wall is free
    bare = make("ant-maze", wall_margin=0.0)
    assert not bare.segments_collide(a[3:], b[3:])[0]
    bare.close()


def test_step_rewards_and_terminates_as_the_batched_functions(env):
    obs, info = env.reset(options={"start": UPPER, "goal": UPPER + [0.3, 0.0]})
    assert obs["observation"].shape == (29,) and obs["achieved_goal"].shape == (2,)
    np.testing.assert_allclose(obs["observation"][:2], obs["achieved_goal"])
    np.testing.assert_allclose(obs["achieved_goal"], UPPER, atol=1e-6)
    obs, reward, terminated, truncated, info = env.step(np.zeros(8))
    # 0.3 m < success_radius 0.45: reached at once
    assert terminated and reward == 1.0 and not truncated and info["success"]
    achieved = np.array([UPPER, UPPER, LOWER])
    desired = np.array([UPPER + [0.3, 0], UPPER + [0.5, 0], UPPER])
    np.testing.assert_array_equal(env.compute_reward(achieved, desired, None), [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(env.compute_terminated(achieved, desired, None), [True, False, False])


def test_goal_only_reset_keeps_the_motion(env):
    env.reset(options={"start": UPPER, "goal": LOWER})
    rng = np.random.default_rng(0)
    for _ in range(20):
        env.step(rng.uniform(-1, 1, 8))
    before = env.unwrapped._ant.data.qvel.copy()
    position = env.unwrapped._ant.data.qpos.copy()
    obs, info = env.reset(options={"goal": UPPER})
    np.testing.assert_array_equal(env.unwrapped._ant.data.qvel, before)
    np.testing.assert_array_equal(env.unwrapped._ant.data.qpos, position)
    np.testing.assert_array_equal(obs["desired_goal"], UPPER.astype(np.float32))
    assert info["num_collisions"] == 0
    # a full reset stands the Ant still at the start
    env.reset(options={"start": LOWER, "goal": UPPER})
    assert not env.unwrapped._ant.data.qvel.any()


def test_wall_contact_is_a_collision_and_a_flip_fails_the_episode(env):
    env.reset(options={"start": UPPER, "goal": LOWER})
    ant = env.unwrapped
    ant._place(np.array([-4.0, 2.2]))  # the torso 0.2 m above the middle wall's top edge: legs on it
    _, _, _, _, info = env.step(np.zeros(8))
    assert info["collision"] and not info["failed"] and not info["success"]
    env.reset(options={"start": UPPER, "goal": LOWER})
    qpos, qvel = ant._ant.data.qpos.copy(), ant._ant.data.qvel.copy()
    qpos[2], qpos[3:7] = 1.0, [0.0, 1.0, 0.0, 0.0]  # rotated 180 degrees about x: upside down
    ant._ant.set_state(qpos, qvel)
    _, _, terminated, truncated, info = env.step(np.zeros(8))
    assert info["failed"] and info["collision"] and truncated and not terminated
    # the next sub-goal stands it up where it lies
    obs, _ = env.reset(options={"goal": LOWER})
    assert ant._ant.data.xmat[ant._torso][8] > 0.99
    np.testing.assert_allclose(obs["achieved_goal"], qpos[:2], atol=1e-5)


@pytest.mark.parametrize(
    "config, named",
    [
        ({"map": "huge"}, "'map'"),
        ({"wall_margin": 3.0}, "'wall_margin'"),
        ({"num_test_tasks": 0}, "'num_test_tasks'"),
        ({"layout": "four-rooms"}, "'layout'"),
    ],
)
def test_bad_config_is_refused_naming_the_key(config, named):
    with pytest.raises(ValueError, match=named):
        make("ant-maze", **config)


def test_tasks_outside_the_maze_or_in_a_wall_are_refused(env):
    with pytest.raises(ValueError, match=r"start \[0.0, 0.0\] lies in a wall"):
        env.reset(options={"start": [0.0, 0.0], "goal": UPPER})
    with pytest.raises(ValueError, match=r"goal \[30.0, 0.0\] lies outside the u-maze maze"):
        env.reset(options={"start": UPPER, "goal": [30.0, 0.0]})
    # a sub-goal in a wall is allowed (a planner's can be): it is only unreachable
    env.reset(options={"start": UPPER, "goal": [0.0, 0.0]})


def test_traversal_carries_the_ants_motion_from_one_sub_goal_to_the_next():
    from copilot_ray.algorithms.sac.traversal_env import TraversalEnv

    # after_failure="continue": the 5-step sub-task fails, and the next one carries on from there
    rules = {"tau_max": 5, "after_failure": "continue"}
    traversal = TraversalEnv({"goal_env": "ant-maze", "goal_env_config": {}, **rules})
    tree = np.array([[UPPER, UPPER + [2.0, 0.0], UPPER + [4.0, 0.0]]], np.float32)
    traversal.load_plan(tree, depth=1, task_ids=np.array([0]))
    traversal.reset()
    rng = np.random.default_rng(0)
    done = False
    while not done:
        *_, terminated, truncated, info = traversal.step(rng.uniform(-1, 1, 8))
        done = terminated or truncated
    ant = traversal.inner._ant
    qvel = ant.data.qvel.copy()
    traversal.reset()  # the layer's second sub-task: same motion, new sub-goal
    np.testing.assert_array_equal(ant.data.qvel, qvel)
    np.testing.assert_allclose(info["subtask_end"], ant.data.qpos[:2], atol=1e-6)


def test_rgb_frame_from_above_with_sub_goal_markers():
    """Off-screen rendering needs an OpenGL backend chosen before MuJoCo loads: a fresh process."""
    code = (
        "import numpy as np\n"
        "from copilot_ray.envs import make\n"
        "e = make('ant-maze', render_mode='rgb_array', render_size=64)\n"
        "e.reset(options={'start': [-4.0, 4.0], 'goal': [-4.0, -4.0]})\n"
        "plain = e.render()\n"
        "e.set_render_path(np.array([[4.0, 4.0], [4.0, -4.0]]))\n"
        "marked = e.render()\n"
        "print(plain.shape, plain.dtype, int((plain != marked).any(axis=2).sum()))\n"
    )
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    if done.returncode != 0 and ("OpenGL" in done.stderr or "EGL" in done.stderr or "gl" in done.stderr):
        pytest.skip(f"no off-screen OpenGL backend here (MUJOCO_GL={env['MUJOCO_GL']}): {done.stderr[-300:]}")
    assert done.returncode == 0, done.stderr[-2000:]
    shape, dtype, changed = done.stdout.split(")")[0] + ")", *done.stdout.split(")")[1].split()
    assert shape == "(64, 64, 3)" and dtype == "uint8"
    assert int(changed) > 0  # the markers show


@pytest.mark.ray
def test_copilot_and_sac_train_and_evaluate_on_the_ant_maze(ray_session):
    """One short iteration each: the planner plans in metres among the walls, the traversal runs on
    MuJoCo, and the evaluation reports success and the return R x reached."""
    from copilot_ray import keys
    from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
    from copilot_ray.algorithms.sac.algorithm import GoalSACConfig

    common = {"tau_max": 10, "task_batch_size": 1, "reward_scale": 1000.0, "eval_num_tasks": 2}
    copilot = (
        CoPilotConfig()
        .environment("ant-maze", env_config={"num_train_tasks": 8})
        .copilot(
            tree_depth=1,
            repetitions=1,
            planner_task_batch_size=4,
            planner_warm_start=2,
            eval_interval=1,
            eval_tree_tasks=1,
            **common,
        )
        .debugging(seed=0)
        .build_algo()
    )
    try:
        result = copilot.train()
        # b = 1, K = 1: 3 sub-tasks of <= 10 steps (fewer when the Ant flips)
        assert 0 < keys.result_value(result, keys.ENV_STEPS) <= 30
        assert 0.0 <= keys.result_value(result, keys.EVAL_SUCCESS) <= 1.0
        assert keys.result_value(result, keys.EVAL_RETURN) in (0.0, 500.0, 1000.0)  # 2 tasks, R = 1000
        trees = copilot.curriculum.planner.sample(
            *copilot.goal_env.unwrapped.tasks("test"), deterministic=True
        )
        assert np.abs(trees).max() <= 10.0  # inside the 20 m x 20 m maze
    finally:
        copilot.stop()
    sac = (
        GoalSACConfig()
        .environment("ant-maze", env_config={"num_train_tasks": 8})
        .agent(eval_interval=1, **common)
        .debugging(seed=0)
        .build_algo()
    )
    try:
        result = sac.train()
        assert 0 < keys.result_value(result, keys.ENV_STEPS) <= 10
        assert keys.result_value(result, keys.EVAL_RETURN) in (0.0, 500.0, 1000.0)
    finally:
        sac.stop()


@pytest.mark.ray
def test_sorb_and_hrl_run_on_the_ant_maze(ray_session):
    """The other two baselines of the paper's Fig. 2d through the same registry: SoRB searches its
    replay graph in metres once pre-trained; HRL proposes sub-goals within its range of the maze."""
    from copilot_ray import keys
    from copilot_ray.algorithms.hrl.algorithm import HRL
    from copilot_ray.algorithms.hrl.config import HRLConfig
    from copilot_ray.algorithms.sorb.algorithm import SoRBConfig
    from copilot_ray.registry import RunContext

    sorb = (
        SoRBConfig()
        .environment("ant-maze", env_config={"num_train_tasks": 8})
        .agent(tau_max=50, task_batch_size=2, reward_scale=1000.0, eval_interval=1, eval_num_tasks=2)
        .training(num_steps_sampled_before_learning_starts=50)
        .search(pretrain_env_steps=50, graph_size=40, max_edge_steps=100, waypoint_steps=25)
        .debugging(seed=0)
        .build_algo()
    )
    try:
        sorb.train()
        result = sorb.train()  # past pre-training: the graph is built at this evaluation
        # (a young critic may keep no edge under the cutoff: then the route is [s0, g])
        assert keys.result_value(result, keys.SORB_GRAPH_S) >= 0
        assert keys.result_value(result, keys.SORB_WAYPOINTS) >= 2
        assert keys.result_value(result, keys.EVAL_RETURN) in (0.0, 500.0, 1000.0)
    finally:
        sorb.stop()
    values = {
        "tau_max": 50,
        "task_batch_size": 2,
        "env_steps_per_iteration": 50,
        "reward_scale": 1000.0,
        "eval_num_tasks": 2,
        "num_steps_sampled_before_learning_starts": 50,
        "low.hidden": [32, 32],
        "high.hidden": [32, 32],
    }
    hrl = HRL(HRLConfig.from_settings(values, RunContext(env_id="ant-maze", env_config={}, seed=0)))
    try:
        metrics = hrl.train()
        assert 50 <= metrics[keys.ENV_STEPS] <= 100
        assert metrics[keys.EVAL_RETURN] in (0.0, 500.0, 1000.0)
        np.testing.assert_allclose(hrl.box.bound, 0.1 * 20.0)  # 0.1 of the 20 m maze per dimension
    finally:
        hrl.stop()
