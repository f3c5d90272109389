"""GoalMazeEnv: gymnasium compliance, blocked moves, success/reward, tasks, speed, rendering."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from copilot_ray.envs import make
from copilot_ray.envs.maze import DEFAULT_LAYOUT, DEFAULTS, GoalMazeEnv, render_maze, shortest_path_lengths

# 4 x 4 cells; the box is x in [0.25, 0.5], y in [0.5, 0.75].
BOX_LAYOUT = "....\n.#..\n....\n....\n"


@pytest.fixture
def box_env(tmp_path):
    path = tmp_path / "box.txt"
    path.write_text(BOX_LAYOUT)
    return make("maze-point", layout=str(path), speed=0.1, max_episode_steps=50).unwrapped


@pytest.mark.filterwarnings("ignore:.*alternative render modes")  # no gymnasium spec: RLlib-style env
def test_check_env_passes():
    check_env(make("maze-point"), skip_render_check=False)
    check_env(make("maze-point", render_mode="rgb_array", render_size=64), skip_render_check=False)


def test_spaces_and_interface():
    env = make("maze-point").unwrapped
    assert isinstance(env, gym.Env) and isinstance(env.observation_space, gym.spaces.Dict)
    for key in ("observation", "achieved_goal", "desired_goal"):
        assert env.observation_space[key].dtype == np.float32
    assert env.goal_dim == 2 and env.goal_space.shape == (2,)
    assert env.nominal_step_distance == DEFAULTS["speed"]
    assert env.success_radius == 0.025 and env.max_episode_steps == 1000
    assert env.layout.name == DEFAULT_LAYOUT


def test_blocked_move_stays_and_reports_collision(box_env):
    obs, info = box_env.reset(options={"start": [0.2, 0.625], "goal": [0.875, 0.125]})
    assert info["collision"] is False
    obs2, reward, terminated, truncated, info = box_env.step(np.array([1.0, 0.0], dtype=np.float32))
    assert info["collision"] is True and info["num_collisions"] == 1
    np.testing.assert_array_equal(obs2["observation"], obs["observation"])
    assert reward == 0.0 and not terminated and not truncated
    obs3, *_, info = box_env.step(np.array([0.0, -1.0], dtype=np.float32))  # a free move goes through
    assert info["collision"] is False
    np.testing.assert_allclose(obs3["observation"], [0.2, 0.525], atol=1e-6)


def test_move_out_of_square_is_blocked(box_env):
    obs, _ = box_env.reset(options={"start": [0.95, 0.1], "goal": [0.1, 0.1]})
    obs2, *_, info = box_env.step(np.array([1.0, 0.0], dtype=np.float32))
    assert info["collision"] and np.array_equal(obs2["observation"], obs["observation"])


def test_action_is_clipped_to_the_unit_disc(box_env):
    box_env.reset(options={"start": [0.7, 0.3], "goal": [0.1, 0.1]})
    obs, *_ = box_env.step(np.array([1.0, 1.0], dtype=np.float32))
    moved = np.linalg.norm(obs["observation"] - np.array([0.7, 0.3]))
    assert moved == pytest.approx(box_env.nominal_step_distance, abs=1e-6)


def test_success_reward_and_termination(box_env):
    box_env.reset(options={"start": [0.8, 0.2], "goal": [0.88, 0.2]})
    _, reward, terminated, truncated, info = box_env.step(np.array([1.0, 0.0], dtype=np.float32))
    assert terminated and not truncated and reward == 1.0 and info["success"] is True


def test_no_success_after_a_collision(box_env):
    box_env.reset(options={"start": [0.2, 0.625], "goal": [0.2, 0.53]})
    _, _, _, _, info = box_env.step(np.array([1.0, 0.0], dtype=np.float32))  # into the box: blocked
    assert info["collision"]
    _, reward, terminated, _, info = box_env.step(np.array([0.0, -1.0], dtype=np.float32))
    assert terminated and reward == 1.0 and info["success"] is False
    _, info = box_env.reset(options={"start": [0.2, 0.625], "goal": [0.2, 0.53]})
    assert info["num_collisions"] == 0  # reset clears the episode's collisions


def test_truncation_inside_the_env(tmp_path):
    env = make("maze-point", max_episode_steps=3)
    env.reset(seed=0)
    flags = [env.step(np.zeros(2, dtype=np.float32))[3] for _ in range(3)]
    assert flags == [False, False, True]


def test_compute_reward_batched_and_single():
    env = make("maze-point", goal_reward=2.5).unwrapped
    a = np.array([[0.1, 0.1], [0.5, 0.5], [0.3, 0.3]], dtype=np.float32)
    b = np.array([[0.11, 0.1], [0.9, 0.5], [0.3, 0.3 + 0.025]], dtype=np.float32)
    r = env.compute_reward(a, b, {})
    assert r.shape == (3,)
    np.testing.assert_allclose(r, [2.5, 0.0, 2.5])
    single = env.compute_reward(a[1], b[1], {})
    assert isinstance(single, float) and single == 0.0
    assert env.goal_distance(a, b).shape == (3,)
    assert env.segments_collide(a, b).shape == (3,) and env.segments_collide(a, b).dtype == bool


def test_task_sampling_is_deterministic_and_valid():
    env = make("maze-point").unwrapped
    s1, g1 = env.sample_tasks(50, "train", seed=3)
    s2, g2 = env.sample_tasks(50, "train", seed=3)
    s3, _ = env.sample_tasks(50, "train", seed=4)
    np.testing.assert_array_equal(s1, s2)
    np.testing.assert_array_equal(g1, g2)
    assert not np.array_equal(s1, s3)
    assert s1.dtype == np.float32 and s1.shape == (50, 2)
    for points in (s1, g1):
        assert (env.obstacles.clearance(points) >= env.success_radius).all()
    assert (env.goal_distance(s1, g1) >= 2 * env.success_radius).all()
    assert np.isfinite(shortest_path_lengths(env, s1, g1)).all()


def test_fixed_splits_are_disjoint_and_sized():
    env = make("maze-point", num_train_tasks=30, num_test_tasks=10, task_seed=5).unwrapped
    (ts, tg), (es, eg) = env.tasks("train"), env.tasks("test")
    assert ts.shape == (30, 2) and es.shape == (10, 2)
    assert not ({tuple(p) for p in ts.tolist()} & {tuple(p) for p in es.tolist()})
    assert not ({tuple(p) for p in tg.tolist()} & {tuple(p) for p in eg.tolist()})
    other = make("maze-point", num_train_tasks=30, num_test_tasks=10, task_seed=5).unwrapped
    np.testing.assert_array_equal(other.tasks("test")[1], eg)
    with pytest.raises(ValueError, match="uniform"):
        env.tasks("uniform")


def test_reset_draws_from_the_configured_split():
    env = make("maze-point", num_train_tasks=20, num_test_tasks=5, task_split="test").unwrapped
    starts, goals = env.tasks("test")
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        i = np.flatnonzero((starts == obs["observation"]).all(axis=1))
        assert len(i) == 1 and np.array_equal(goals[i[0]], obs["desired_goal"])
    uniform = make("maze-point", task_split="uniform").unwrapped
    o1, _ = uniform.reset(seed=1)
    o2, _ = uniform.reset(seed=1)
    np.testing.assert_array_equal(o1["desired_goal"], o2["desired_goal"])


def test_set_task_persists_until_cleared():
    env = make("maze-point").unwrapped
    env.set_task([0.1, 0.1], [0.3, 0.1])
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        np.testing.assert_allclose(obs["observation"], [0.1, 0.1])
        np.testing.assert_allclose(obs["desired_goal"], [0.3, 0.1])
    obs, _ = env.reset(options={"start": [0.2, 0.2], "goal": [0.4, 0.1]})  # options win
    np.testing.assert_allclose(obs["observation"], [0.2, 0.2])
    env.clear_task()
    obs, _ = env.reset(seed=0)
    assert not np.allclose(obs["observation"], [0.1, 0.1])


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"start": [0.1, 0.1]}, "both"),
        ({"start": [0.1, 0.1], "goal": [0.2, 0.2], "speed": 1}, "'speed'"),
        ({"start": [0.1, 0.1, 0.1], "goal": [0.2, 0.2]}, "start"),
        ({"start": [0.1, 0.1], "goal": [1.5, 0.5]}, "goal .* outside"),
    ],
)
def test_bad_reset_options(options, match):
    with pytest.raises(ValueError, match=match):
        make("maze-point").reset(options=options)


def test_default_speed_gives_long_horizon_tasks():
    """The paper: an agent needs >= 200 steps on average (default layout, default test tasks)."""
    env = make("maze-point").unwrapped
    starts, goals = env.tasks("test")
    lengths = shortest_path_lengths(env, starts, goals)
    steps = np.ceil((lengths - env.success_radius) / env.nominal_step_distance)
    assert steps.mean() >= 200
    assert steps.max() < env.max_episode_steps
    assert env.segments_collide(starts, goals).mean() > 0.5  # straight lines usually fail


def test_env_config_errors_name_the_key():
    with pytest.raises(ValueError, match=r"'speeed'.*valid keys:.*speed"):
        make("maze-point", speeed=0.01)
    with pytest.raises(ValueError, match=r"'success_radius'.*-1"):
        make("maze-point", success_radius=-1)
    with pytest.raises(ValueError, match=r"'task_split'"):
        make("maze-point", task_split="valdiation")
    with pytest.raises(ValueError, match=r"'max_episode_steps'"):
        make("maze-point", max_episode_steps=0)


class FakeEnvContext(dict):
    """Like RLlib's EnvContext: a dict with extra attributes."""

    worker_index = 3
    num_workers = 4
    vector_index = 0


def test_accepts_an_env_context_mapping():
    env = GoalMazeEnv(FakeEnvContext(layout="u-maze", speed=0.01))
    assert env.layout.name == "u-maze" and env.nominal_step_distance == 0.01


def test_render_rgb_array_and_render_maze():
    env = make("maze-point", render_mode="rgb_array", render_size=96).unwrapped
    env.reset(seed=0)
    plain = env.render()
    assert plain.shape == (96, 96, 3) and plain.dtype == np.uint8
    env.set_render_path(np.array([[0.1, 0.1], [0.5, 0.9], [0.9, 0.1]]))
    with_path = env.render()
    assert (with_path != plain).any()
    image = render_maze(
        "four-rooms", agent=[0.1, 0.1], goal=[0.9, 0.9], paths=[np.array([[0.1, 0.1], [0.9, 0.9]])], size=64
    )
    assert image.shape == (64, 64, 3) and image.dtype == np.uint8
    assert (image == 255).any() and (image < 100).any()
    assert make("maze-point").render() is None


def test_goal_inside_an_obstacle_is_allowed_but_unreachable():
    # A planner's sub-goal may land in an obstacle: the sub-task then simply cannot be completed.
    env = make("maze-point", layout="u-maze")
    inner = env.unwrapped
    goal = next(
        np.array([x, y])
        for x in np.linspace(0.05, 0.95, 19)
        for y in np.linspace(0.05, 0.95, 19)
        if inner.agent_geometry.clearance(inner.obstacles, np.array([[x, y]]))[0] <= 0
    )
    starts, _ = inner.tasks("train")
    obs, _ = env.reset(options={"start": starts[0], "goal": goal})
    np.testing.assert_allclose(obs["desired_goal"], goal, atol=1e-6)


def _corridors(tmp_path):
    """Rows of free cells 0.05 high joined at the right end: a point fits (its clearance reaches 0.025 in
    the middle of a corridor), a 0.05 stick or a 0.06 snake does not keep 0.025 from the walls."""
    rows = ["." * 20 if r % 2 == 0 else "#" * 19 + "." for r in range(20)]
    path = tmp_path / "corridors.txt"
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("agent", ["rigid", "snake"])
def test_a_body_that_fits_nowhere_is_refused_when_the_env_is_built(tmp_path, agent):
    from copilot_ray.envs.maze.layouts import BodyDoesNotFitError, LayoutError

    layout = _corridors(tmp_path)
    make("maze-point", layout=str(layout)).close()  # the point fits
    with pytest.raises(BodyDoesNotFitError, match=rf"maze-{agent} agent's body \(a .*\) fits nowhere") as err:
        make(f"maze-{agent}", layout=str(layout))
    assert str(layout) in str(err.value) and isinstance(err.value, LayoutError)
