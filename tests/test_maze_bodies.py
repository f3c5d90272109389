"""maze-rigid and maze-snake: bodies whose motion checks never report a colliding motion free."""

from __future__ import annotations

import numpy as np
import pytest

from copilot_ray.envs import make
from copilot_ray.envs.maze import Obstacles, builtin_layout_names, load_layout
from copilot_ray.envs.maze.bodies import segment_clearance
from copilot_ray.envs.maze.rigid_body import LENGTH, RigidBody, stick_endpoints
from copilot_ray.envs.maze.snake import JOINT_LIMIT, LINK, Snake, joints

BODIES = {"rigid": RigidBody, "snake": Snake}


def static_collides(body, obstacles: Obstacles, configs: np.ndarray) -> np.ndarray:
    """The body at each configuration against boxes and border, by the exact segment test alone."""
    if isinstance(body, RigidBody):
        return obstacles.segments_collide(*stick_endpoints(configs, body.length))
    pts = joints(configs)
    links = obstacles.segments_collide(pts[:, :-1].reshape(-1, 2), pts[:, 1:].reshape(-1, 2))
    return links.reshape(len(pts), pts.shape[1] - 1).any(axis=1)


def reference_motion_collides(body, obstacles: Obstacles, a, b, samples: int = 2000) -> np.ndarray:
    """A much finer reference: the body at `samples` evenly spaced configurations along each motion,
    each tested exactly (its segments against boxes and border)."""
    out = np.zeros(len(a), dtype=bool)
    if not len(a):
        return out
    # Many configurations per call (all motions x a chunk of t), so that 100k samples stay quick.
    for ts in np.array_split(np.linspace(0.0, 1.0, samples), max(1, samples * len(a) // 200_000)):
        t = np.tile(ts, len(a))
        hit = static_collides(
            body, obstacles, body.interpolate(np.repeat(a, len(ts), 0), np.repeat(b, len(ts), 0), t)
        )
        out |= hit.reshape(len(a), len(ts)).any(axis=1)
    return out


def random_motions(rng, n: int, scale: float, dim: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Motions from random configurations (joint angles within the snake's limits), `scale` long."""
    angles = rng.uniform(-JOINT_LIMIT, JOINT_LIMIT, (n, dim - 2))
    a = np.column_stack([rng.uniform(0.02, 0.98, (n, 2)), angles])
    step = np.column_stack([rng.normal(0, scale, (n, 2)), rng.normal(0, 40 * scale, (n, dim - 2))])
    b = a + step
    b[:, 3:] = np.clip(b[:, 3:], -JOINT_LIMIT, JOINT_LIMIT)
    return a, b


@pytest.mark.parametrize("agent", sorted(BODIES))
@pytest.mark.parametrize("layout", builtin_layout_names())
def test_no_colliding_motion_is_reported_free_on_any_builtin_layout(layout, agent):
    obstacles = Obstacles.from_layout(load_layout(layout))
    body = BODIES[agent](speed=0.0025)
    rng = np.random.default_rng(0)
    for scale in (0.003, 0.02, 0.06):  # one step, a few steps, a planner's segment
        a, b = random_motions(rng, 200, scale, body.config_dim)
        ours = body.motions_collide(obstacles, a, b)
        reference = reference_motion_collides(body, obstacles, a, b)
        missed = reference & ~ours
        assert not missed.any(), (
            f"{missed.sum()} colliding motions reported free ({agent}, {layout}, {scale})"
        )
        # Conservative, not paranoid: where we say "collides" and the reference does not, a 50x finer
        # reference must mostly agree with us (it did find the 2000-sample reference missing a graze).
        free = ~reference
        doubt = np.flatnonzero(ours & free)
        confirmed = reference_motion_collides(body, obstacles, a[doubt], b[doubt], samples=100_000)
        false_alarms = len(doubt) - int(confirmed.sum())
        assert free.sum() > 10 and false_alarms <= 0.02 * free.sum(), (agent, layout, scale, false_alarms)


def test_a_wall_thinner_than_any_sampling_step_is_not_jumped():
    thin = Obstacles(np.array([[0.5, 0.0]]), np.array([[0.5005, 1.0]]))  # 0.0005 wide, full height
    body = RigidBody(speed=0.0025)
    a = np.array([[0.3, 0.5, 0.0], [0.3, 0.5, 0.0]])
    b = np.array([[0.7, 0.5, 1.0], [0.45, 0.5, 1.0]])  # across the wall; short of it
    np.testing.assert_array_equal(body.motions_collide(thin, a, b), [True, False])


def test_segment_clearance_is_the_exact_distance():
    obstacles = Obstacles(np.array([[0.4, 0.4]]), np.array([[0.6, 0.6]]))
    # Horizontal stick above the box: 0.05 away. Stick whose end points at the box's corner diagonally.
    a = np.array([[0.45, 0.65], [0.2, 0.2], [0.45, 0.5]])
    b = np.array([[0.55, 0.65], [0.3, 0.3], [0.55, 0.5]])
    d = segment_clearance(obstacles, a, b)
    np.testing.assert_allclose(d[:2], [0.05, np.hypot(0.1, 0.1)], rtol=1e-12)
    assert d[2] == 0.0  # inside the box
    # Against dense sampling of the segment's points: never more, and within the sampling error.
    rng = np.random.default_rng(1)
    p = rng.uniform(0.05, 0.95, (300, 2))
    q = p + rng.normal(0, 0.1, (300, 2))
    ts = np.linspace(0, 1, 801)[:, None, None]
    sampled = obstacles.clearance((p + ts * (q - p)).reshape(-1, 2)).reshape(801, 300).min(axis=0)
    exact = segment_clearance(obstacles, p, q)
    assert (exact <= sampled + 1e-12).all()
    assert np.allclose(exact, sampled, atol=np.linalg.norm(q - p, axis=1).max() / 800 + 1e-12)


def test_distance_wraps_the_angle_and_weights_it_by_the_half_length():
    body = RigidBody(speed=0.0025)
    a, b = np.array([0.5, 0.5, np.pi - 0.1]), np.array([0.5, 0.5, -np.pi + 0.1])
    assert body.distance(a, b) == pytest.approx(0.5 * LENGTH * 0.2)
    assert body.distance(np.zeros(3), np.array([0.3, 0.4, 0.0])) == pytest.approx(0.5)


def test_a_full_step_moves_no_point_more_than_twice_the_speed():
    body = RigidBody(speed=0.01)
    c = np.array([0.5, 0.5, 0.3])
    nxt = body.step(c, np.array([1.0, 1.0, 1.0]))
    ends0, ends1 = np.concatenate(stick_endpoints(c)), np.concatenate(stick_endpoints(nxt))
    assert np.linalg.norm(ends1 - ends0, axis=1).max() <= 2 * body.speed + 1e-12
    assert body.distance(c, nxt) == pytest.approx(body.nominal_step_distance)


def test_maze_rigid_env_blocks_motions_into_walls_and_keeps_tasks_free():
    env = make("maze-rigid", layout="four-rooms").unwrapped
    assert env.goal_dim == 3 and env.action_space.shape == (3,)
    starts, goals = env.tasks("test")
    geometry = env.agent_geometry
    assert (geometry.clearance(env.obstacles, starts) >= env.success_radius).all()
    assert (geometry.clearance(env.obstacles, goals) >= env.success_radius).all()
    # Upright next to the left border of the empty maze, pushing left: blocked and reported.
    env = make("maze-rigid", layout="empty").unwrapped
    env.reset(options={"start": [0.03, 0.5, np.pi / 2], "goal": [0.5, 0.5, 0.0]})
    before = env._config_now.copy()
    for _ in range(20):
        _, _, _, _, info = env.step(np.array([-1.0, 0.0, 0.0], np.float32))
    assert info["collision"] and env._config_now[0] > 0.0
    assert env.render() is None  # no render mode
    picture = make("maze-rigid", render_mode="rgb_array").unwrapped
    picture.reset()
    assert picture.render().shape == (256, 256, 3)
    assert before[2] == pytest.approx(np.pi / 2)


def test_start_inside_a_wall_is_refused_naming_it():
    env = make("maze-rigid", layout="four-rooms").unwrapped
    with pytest.raises(ValueError, match=r"start \[.*\] lies in an obstacle or outside the maze"):
        env.reset(options={"start": [0.5, 0.5, 0.0], "goal": [0.2, 0.2, 0.0]})


@pytest.mark.parametrize("env_id", ["maze-rigid", "maze-snake"])
def test_a_spec_on_a_body_maze_builds_a_copilot_config(env_id):
    from copilot_ray.sweep_spec import build_algorithm_config, parse_spec

    spec = parse_spec(
        {
            "name": "body",
            "env": {"id": env_id, "config": {"layout": "four-rooms"}},
            "config": {"tree_depth": 2},
            "stop": {"env_steps": 100, "min_evaluations": 1},
        }
    )
    config = build_algorithm_config({"seed": 0}, spec)
    config.validate()
    assert config.goal_env == env_id and config.env_config["goal_env_config"] == {"layout": "four-rooms"}


def test_snake_joints_chain_the_links_and_the_distance_weights_each_joint_by_its_reach():
    pts = joints(np.array([0.5, 0.5, 0.0, np.pi / 2, -np.pi / 2]))[0]
    np.testing.assert_allclose(pts, [[0.5, 0.5], [0.52, 0.5], [0.52, 0.52], [0.54, 0.52]], atol=1e-12)
    body = Snake(speed=0.0025)
    a = np.array([0.5, 0.5, np.pi - 0.1, 0.0, 0.0])
    b = np.array([0.5, 0.5, -np.pi + 0.1, 0.3, 0.0])
    assert body.distance(a, b) == pytest.approx(np.hypot(3 * LINK * 0.2, 2 * LINK * 0.3))
    nxt = body.step(np.array([0.5, 0.5, 0.0, 0.0, 0.0]), np.ones(5))
    moved = np.linalg.norm(joints(nxt)[0] - joints(np.array([0.5, 0.5, 0.0, 0.0, 0.0]))[0], axis=1)
    assert moved.max() <= 4 * body.speed + 1e-12  # base + three joints, each at most `speed`
    assert body.distance(np.array([0.5, 0.5, 0.0, 0.0, 0.0]), nxt) == pytest.approx(
        body.nominal_step_distance
    )
    limited = body.step(np.array([0.5, 0.5, 0.0, JOINT_LIMIT, 0.0]), np.ones(5))
    assert limited[3] == JOINT_LIMIT  # joints stop at their limits


def test_maze_snake_env_runs_renders_and_keeps_tasks_free():
    env = make("maze-snake", layout="four-rooms", render_mode="rgb_array").unwrapped
    assert env.goal_dim == 5 and env.action_space.shape == (5,)
    starts, goals = env.tasks("test")
    assert (env.agent_geometry.clearance(env.obstacles, starts) >= env.success_radius).all()
    env.reset()
    _, _, _, _, info = env.step(np.ones(5, np.float32))
    assert set(info) >= {"collision", "success", "distance"}
    assert env.render().shape == (256, 256, 3)
