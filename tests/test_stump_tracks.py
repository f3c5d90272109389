"""walker-stumps: Box2D's BipedalWalker on stump tracks, goal-conditioned (copilot_ray/envs/stump_tracks.py)."""

import numpy as np
import pytest
from gymnasium.envs.box2d import bipedal_walker as bw

from copilot_ray.envs import make
from copilot_ray.envs.stump_tracks import (
    FAR_END,
    LEG_HEIGHTS,
    PARAM_RANGES,
    START_X,
    GoalStumpTracksEnv,
    Track,
    evaluate_mastery,
    evaluation_distributions,
)


@pytest.fixture
def env():
    e = make(
        "walker-stumps", num_eval_distributions=4, tracks_per_distribution=2, train_tracks_per_distribution=3
    )
    yield e
    e.close()


def test_registry_builds_it_with_the_goal_interface(env):
    assert isinstance(env, GoalStumpTracksEnv) and env.goal_only_reset
    obs, info = env.reset(seed=0)
    assert obs["observation"].shape == (25,) and obs["observation"].dtype == np.float32
    assert obs["achieved_goal"].shape == obs["desired_goal"].shape == (1,) and env.goal_dim == 1
    assert obs["observation"][24] == obs["achieved_goal"][0]  # hull x, in the goal's units
    assert abs(obs["achieved_goal"][0] - START_X) < 0.05 and obs["desired_goal"][0] == np.float32(FAR_END)
    assert env.track in env.tracks("train")  # a plain reset: a training track
    starts, goals = env.tasks("train")
    assert starts.shape == goals.shape == (4 * 3, 1) and starts.dtype == goals.dtype == np.float32
    assert (starts == np.float32(START_X)).all() and (goals == np.float32(FAR_END)).all()
    assert len(env.tasks("test")[0]) == 4 * 2
    a, b = np.zeros((5, 1)), np.arange(5.0)[:, None]
    assert env.goal_distance(a, b).tolist() == [0, 1, 2, 3, 4]
    assert env.segments_collide(a, b).tolist() == [False] * 5
    assert 0 < env.nominal_step_distance < 0.5 and env.goal_space.high[0] == np.float32(FAR_END)


def test_stumps_follow_the_track_distribution():
    env = GoalStumpTracksEnv()
    heights, gaps = [], []
    for seed in range(4):
        env.reset(options={"track": (1.5, 0.8, seed)})
        heights.append(env.stump_heights())
        left, right = env.stumps[:, 0], env.stumps[:, 1]
        assert left[0] == pytest.approx(bw.TERRAIN_STARTPAD * bw.TERRAIN_STEP)  # after the start pad
        assert np.allclose(right - left, bw.TERRAIN_STEP)  # one terrain step wide
        gaps.append(left[1:] - right[:-1])
    heights = np.concatenate(heights)
    assert len(heights) > 200
    assert abs(heights.mean() - 1.5) < 0.03 and 0.08 < heights.std() < 0.12  # N(1.5, 0.1)
    assert np.allclose(np.concatenate(gaps), 0.8)  # the spacing, exactly
    # Low means are clipped at the original's floor; a track is the same terrain every time.
    env.reset(options={"track": (0.0, 6.0, 3)})
    low = env.stump_heights()
    assert low.min() == pytest.approx(0.05) and np.isclose(low, 0.05).mean() > 0.4
    assert len(env.stumps) < 20  # wide gaps: few stumps
    env.reset(options={"track": (0.0, 6.0, 3)})
    assert np.array_equal(env.stump_heights(), low)
    env.close()


def test_track_sets_are_seeded_and_in_range(env):
    d = env.distributions()
    assert d.shape == (4, 2) and np.array_equal(d, evaluation_distributions(4, 0))
    for j, key in enumerate(("stump_height", "spacing")):
        low, high = PARAM_RANGES[key]
        assert (low <= d[:, j]).all() and (d[:, j] <= high).all()
    assert not np.array_equal(evaluation_distributions(4, 1), d)
    many = evaluation_distributions(2000, 0)
    assert abs(many[:, 0].mean() - 1.5) < 0.1 and abs(many[:, 1].mean() - 3.0) < 0.2  # uniform
    train, test = env.tracks("train"), env.tracks("test")
    assert {(t.stump_height, t.spacing) for t in train} == {(t.stump_height, t.spacing) for t in test}
    assert not {t.seed for t in train} & {t.seed for t in test}
    assert make("walker-stumps", track=(1.0, 2.0)).distributions().tolist() == [[1.0, 2.0]]


def test_legs_setting_changes_leg_length():
    standing = {}
    for legs, height in LEG_HEIGHTS.items():
        env = make("walker-stumps", legs=legs)
        env.reset(seed=0)
        for leg in env.legs:
            ys = [v[1] for v in leg.fixtures[0].shape.vertices]
            assert max(ys) - min(ys) == pytest.approx(height, rel=1e-5)
        standing[legs] = env.hull.position.y
        env.close()
    assert standing["short"] < standing["default"] < standing["long"]
    assert bw.LEG_H == 34 / bw.SCALE and bw.LEG_FD.shape.vertices[2][1] == pytest.approx(17 / bw.SCALE)


@pytest.mark.parametrize(
    ("config", "named"),
    [
        ({"legz": "short"}, "'legz'"),
        ({"legs": "tiny"}, "'tiny'"),
        ({"track": (3.5, 1.0)}, "stump_height = 3.5"),
        ({"track": (1.0, -0.5)}, "spacing = -0.5"),
        ({"track": (1.0, 6.01)}, "spacing = 6.01"),
        ({"track": "easy"}, "'easy'"),
        ({"max_episode_steps": 0}, "'max_episode_steps'] = 0"),
        ({"task_split": "val"}, "'val'"),
        ({"num_eval_distributions": 2.5}, "2.5"),
        ({"render_mode": "human"}, "'human'"),
        ({"success_radius": -1}, "'success_radius'] = -1"),
    ],
)
def test_bad_config_is_refused_naming_key_and_value(config, named):
    with pytest.raises(ValueError) as err:
        make("walker-stumps", **config)
    key = next(iter(config))
    assert f"'{key}'" in str(err.value) and named in str(err.value)


def test_bad_reset_options_are_refused(env):
    env.reset(seed=0)
    with pytest.raises(ValueError, match="'goal'.*-3"):
        env.reset(options={"goal": [-3.0]})
    with pytest.raises(ValueError, match="'track'.*stump_height = 4"):
        env.reset(options={"track": (4, 1.0, 0)})
    with pytest.raises(ValueError, match="'start' needs 'goal'"):
        env.reset(options={"start": [START_X]})
    with pytest.raises(ValueError, match="'speed'"):
        env.reset(options={"speed": 1})


def test_goal_only_reset_keeps_the_state_and_the_track(env):
    env.reset(seed=3, options={"track": (2.0, 1.0, 5)})
    rng = np.random.default_rng(0)
    for _ in range(15):
        obs, *_ = env.step(rng.uniform(-0.3, 0.3, 4))
    stumps = env.stumps.copy()
    hull = (tuple(env.hull.position), tuple(env.hull.linearVelocity), env.hull.angle)
    joints = [j.angle for j in env.joints]
    new, info = env.reset(options={"goal": [30.0]})
    assert (tuple(env.hull.position), tuple(env.hull.linearVelocity), env.hull.angle) == hull
    assert [j.angle for j in env.joints] == joints
    assert np.array_equal(new["observation"], obs["observation"]) and new["desired_goal"][0] == 30.0
    assert env.track == Track(2.0, 1.0, 5) and np.array_equal(env.stumps, stumps)
    # A fresh task (start on the start pad) draws a new track; a mid-track start keeps this one.
    env.reset(options={"start": [25.0], "goal": [35.0]})
    assert env.track == Track(2.0, 1.0, 5) and abs(env.hull.position.x - 25.0) < 0.05
    env.reset(options={"start": [START_X], "goal": [FAR_END]})
    assert env.track in env.tracks("train")


def test_fall_is_reported_and_truncates_and_goal_only_reset_stands_it_up(env):
    env.reset(seed=1, options={"track": (0.5, 3.0, 1)})
    for _ in range(300):  # no torque: the knees give way and the hull hits the ground
        obs, reward, terminated, truncated, info = env.step(np.zeros(4))
        if truncated or terminated:
            break
    assert truncated and not terminated and reward == 0.0
    assert info["fallen"] and info["failed"] and info["collision"] and info["walker_reward"] == -100
    x = obs["achieved_goal"][0]
    env.reset(options={"goal": [50.0]})
    assert not env.game_over and abs(env.hull.position.x - x) < 0.05 and env.track == Track(0.5, 3.0, 1)
    _, _, _, truncated, info = env.step(np.zeros(4))
    assert not truncated and not info["fallen"]


def test_compute_reward_batched_agrees_with_step():
    env = make("walker-stumps", success_radius=0.1)
    rng = np.random.default_rng(1)
    achieved, desired, rewards, terminated = [], [], [], []
    for goal in (START_X, START_X + 0.05, START_X + 0.3, START_X + 1.0, START_X - 0.5):
        env.reset(seed=2, options={"start": [START_X], "goal": [goal]})
        for _ in range(40):
            obs, reward, term, trunc, _ = env.step(rng.uniform(-1, 1, 4))
            achieved.append(obs["achieved_goal"])
            desired.append(obs["desired_goal"])
            rewards.append(reward)
            terminated.append(term)
            if term or trunc:
                break
    achieved, desired = np.array(achieved), np.array(desired)
    assert any(terminated) and not all(terminated)
    assert np.array_equal(env.compute_reward(achieved, desired, None), np.array(rewards))
    assert np.array_equal(env.compute_terminated(achieved, desired, None), np.array(terminated))
    assert set(rewards) <= {0.0, 1.0} and np.array(rewards)[np.array(terminated)].min() == 1.0
    env.close()


def test_render_returns_a_frame_with_the_planned_subgoals():
    env = make("walker-stumps", render_mode="rgb_array", track=(1.0, 1.0))
    env.reset(seed=0)
    env.step(np.zeros(4))
    env.set_render_path([[START_X + 2.0], [START_X + 5.0], [60.0]])  # the last one is off screen
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.shape == (400, 600, 3) and frame.dtype == np.uint8
    orange = (frame == [255, 140, 0]).all(axis=-1)
    assert len(np.unique(np.nonzero(orange)[1])) == 2 * 5  # two markers in view, 5 pixels wide each
    env.set_render_path(None)
    assert not (env.render() == [255, 140, 0]).all(axis=-1).any()
    env.close()


def test_mastery_evaluation_of_a_trivial_policy():
    calls = []

    def still(obs):
        calls.append(obs.shape)
        return np.zeros((len(obs), 4))

    result = evaluate_mastery(still, {"num_eval_distributions": 3}, tracks_per_distribution=2, batch_size=4)
    assert result.distributions.shape == (3, 2) and result.returns.shape == result.fallen.shape == (3, 2)
    assert result.mastered.shape == (3,) and result.mastered.dtype == bool and not result.mastered.any()
    assert result.mastered_fraction == 0.0 and (result.returns < 0).all()
    assert (result.fallen | (result.steps == 2000)).all() and result.fallen.any()
    assert calls[0] == (4, 26)  # concat(observation, goal), the envs in lockstep
    assert {shape[0] for shape in calls} <= {1, 2, 3, 4}
    again = evaluate_mastery(still, {"num_eval_distributions": 3}, tracks_per_distribution=2, batch_size=6)
    assert np.array_equal(again.returns, result.returns)  # seeded by the tracks, any batch size


def test_walker_reward_weight_reports_the_walkers_reward_as_the_dense_one():
    env = make("walker-stumps", walker_reward_weight=2.0)
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.ones(4))
    assert info["dense_reward"] == pytest.approx(2.0 * info["walker_reward"]) and info["walker_reward"] != 0
    assert reward == 0.0  # the step's own reward stays the sparse goal reward (HER recomputes it)
    env.close()
    with pytest.raises(ValueError, match="'walker_reward_weight'"):
        make("walker-stumps", walker_reward_weight=-1.0)


@pytest.mark.parametrize("env_id, legs", [("walker-stumps-short", "short"), ("walker-stumps-long", "long")])
def test_each_leg_setting_has_an_env_id(env_id, legs):
    env = make(env_id)
    assert env.config["legs"] == legs
    env.close()


def test_mastery_follows_the_plan_by_the_hulls_position():
    """With a plan the agent is conditioned on the first waypoint more than success_radius ahead of
    the hull (the last one at the end), as a traversal of the track's sub-goals would."""
    env = make("walker-stumps", num_eval_distributions=1, tracks_per_distribution=1)
    seen = []

    def still(flat):
        seen.append(flat[:, 25:].copy())  # goal, then goal - achieved
        return np.zeros((len(flat), 4))

    path = np.array([[START_X], [10.0], [30.0], [FAR_END]])
    env.mastery(still, path, with_delta=True)
    goal, delta = seen[0][:, 0], seen[0][:, 1]
    assert goal[0] == pytest.approx(10.0) and delta[0] == pytest.approx(10.0 - START_X, abs=0.1)
    assert all(g[0, 0] == pytest.approx(10.0) for g in seen)  # a still walker never gets past it
    env.mastery(still, None)
    assert seen[-1].shape == (1, 1) and seen[-1][0, 0] == pytest.approx(FAR_END)  # alone: the far end
    env.close()


@pytest.mark.ray
def test_copilot_and_sac_report_the_mastered_share_on_the_walker(ray_session):
    """One short iteration each on the short-legged walker: the planner plans along the track (1-d),
    the traversal runs on Box2D with the walker's reward added, and the evaluation walks the evaluation
    tracks and logs the mastered share and the walker's mean return."""
    from copilot_ray import keys
    from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
    from copilot_ray.algorithms.sac.algorithm import GoalSACConfig

    env_config = {"num_eval_distributions": 2, "tracks_per_distribution": 1, "walker_reward_weight": 1.0}
    common = {
        "tau_max": 20,
        "task_batch_size": 1,
        "reward_scale": 200.0,
        "eval_interval": 1,
        "eval_num_tasks": 1,
    }
    copilot = dict(
        tree_depth=2, repetitions=1, planner_task_batch_size=2, planner_warm_start=2, eval_tree_tasks=1
    )
    for cls, extra in ((CoPilotConfig, copilot), (GoalSACConfig, {})):
        algo = (
            cls()
            .environment("walker-stumps-short", env_config=env_config)
            .agent(**common, **extra)
            .debugging(seed=0)
            .build_algo()
        )
        try:
            result = algo.train()
            assert keys.result_value(result, keys.ENV_STEPS) > 0
            assert keys.result_value(result, keys.EVAL_MASTERED) == 0.0  # an untrained walker masters nothing
            assert keys.result_value(result, keys.EVAL_ENV_RETURN) < 0  # it falls: -100
            if cls is CoPilotConfig:
                tree = algo.curriculum.planner.sample(
                    algo.test_starts[:1], algo.test_goals[:1], deterministic=True
                )
                assert tree.shape == (1, 5, 1)
        finally:
            algo.stop()


@pytest.mark.ray
def test_sorb_runs_on_the_walker_and_reports_the_mastered_share(ray_session):
    """The third method of the paper's Fig. 3 through the same registry: once pre-trained, SoRB searches
    its replay graph along the track (1-d waypoints in hull x) and its evaluation walks the evaluation
    tracks like the others'."""
    from copilot_ray import keys
    from copilot_ray.algorithms.sorb.algorithm import SoRBConfig

    sorb = (
        SoRBConfig()
        .environment("walker-stumps", env_config={"num_eval_distributions": 2, "tracks_per_distribution": 1})
        .agent(tau_max=30, task_batch_size=1, reward_scale=200.0, eval_interval=1, eval_num_tasks=1)
        .training(num_steps_sampled_before_learning_starts=30)
        .search(pretrain_env_steps=30, graph_size=20, max_edge_steps=50, waypoint_steps=15)
        .debugging(seed=0)
        .build_algo()
    )
    try:
        sorb.train()
        result = sorb.train()  # past pre-training: the graph is built at this evaluation
        assert keys.result_value(result, keys.SORB_GRAPH_S) >= 0
        assert keys.result_value(result, keys.SORB_WAYPOINTS) >= 2  # at least [s0, g]
        assert keys.result_value(result, keys.EVAL_MASTERED) == 0.0  # an untrained walker masters nothing
        assert keys.result_value(result, keys.EVAL_ENV_RETURN) < 0  # it falls
    finally:
        sorb.stop()
