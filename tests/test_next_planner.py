"""NEXT (copilot_ray.planning.next_planner and algorithm `next`): the search solves with the env's own
counted checks on every maze agent, learned guidance beats uniform sampling on a corridor, a restored
trial continues identically, and bad settings are refused by name. Tiny layouts and budgets only."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from copilot_ray.envs import make
from copilot_ray.planning.next_planner import (
    ConfigSpace,
    NEXTPlanner,
    SearchSettings,
    TrainSettings,
    padded_paths,
    rrt_star_demonstrations,
)
from copilot_ray.planning.path_metrics import CountedChecks, score_paths
from copilot_ray.registry import RunContext
from copilot_ray.sweep_spec import SpecError, parse_spec

# A zigzag corridor (7 x 7 cells, one cell wide): most straight lines between two tasks' ends collide.
ZIGZAG = ".......\n######.\n.......\n.######\n.......\n######.\n.......\n"


@pytest.fixture(autouse=True)
def one_thread():
    """Tiny networks: one torch thread (the machine's other cores are busy)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def zigzag(tmp_path_factory):
    path = tmp_path_factory.mktemp("layouts") / "zigzag.txt"
    path.write_text(ZIGZAG)
    env = make("maze-point", layout=str(path), num_train_tasks=20, num_validation_tasks=1, num_test_tasks=8)
    yield env
    env.close()


@pytest.mark.parametrize("agent", ["point", "rigid", "snake"])
def test_the_search_solves_with_free_paths_and_counts_every_check_through_the_env(agent):
    env = make(f"maze-{agent}", layout="empty", num_train_tasks=2, num_validation_tasks=1, num_test_tasks=3)
    maze = env.unwrapped
    counted = CountedChecks(maze.segments_collide)
    space = ConfigSpace.from_env(env)
    planner = NEXTPlanner(space, counted, maze.success_radius, SearchSettings(max_iterations=1500), seed=0)
    starts, goals = (x.astype(np.float64) for x in maze.tasks("test"))
    for guided in (False, True):  # uniform (RRT*), and guided by the untrained model
        before = counted.count
        results = [planner.search(s, g, guided=guided) for s, g in zip(starts, goals, strict=True)]
        assert all(r.solved for r in results), (agent, guided)
        assert counted.count - before == sum(r.checks for r in results) > 0  # every check went to the env
        for r, s in zip(results, starts, strict=True):
            np.testing.assert_allclose(r.path[0], s)
        scores = score_paths(maze, padded_paths(results), goals)  # the env's own motion check agrees
        assert scores.success.all()
        np.testing.assert_allclose(scores.length, [r.length for r in results])
        steps = maze.goal_distance(
            np.concatenate([r.path[:-1] for r in results]), np.concatenate([r.path[1:] for r in results])
        )
        s = planner.search_settings  # extensions are steered, rewired edges stay within the radius
        assert steps.max() <= s.rewire_factor * s.step + 1e-9
    assert planner.checks == counted.count
    env.close()


def test_steering_and_distance_follow_the_envs_wrapped_weighted_distance():
    env = make("maze-rigid", layout="empty")
    maze = env.unwrapped
    space = ConfigSpace.from_env(env)
    a, b = np.array([0.5, 0.5, 3.0]), np.array([0.5, 0.5, -3.0])
    assert space.dist(a, b) == pytest.approx(maze.goal_distance(a, b))
    new = space.steer(a, b, 0.001)  # the short way round: through the seam, not back across 0
    assert new[2] > 3.0 and maze.goal_distance(a, new) == pytest.approx(0.001)
    dense = space.densify(np.stack([a, b]), 0.001)
    assert len(dense) == 1 + int(np.ceil(maze.goal_distance(a, b) / 0.001))
    assert maze.goal_distance(dense[:-1], dense[1:]).max() <= 0.001 + 1e-12
    env.close()


def test_the_search_is_deterministic_under_a_seed(zigzag):
    maze = zigzag.unwrapped
    (start, *_), (goal, *_) = maze.tasks("test")

    def run(seed):
        planner = NEXTPlanner.for_env(zigzag, SearchSettings(), TrainSettings(hidden=(16,)), seed=seed)
        return planner.search(start, goal)

    first, again, other = run(3), run(3), run(4)
    assert first.checks == again.checks and np.array_equal(first.path, again.path)
    assert (first.checks, first.length) != (other.checks, other.length)


def test_learned_guidance_spends_fewer_checks_than_uniform_sampling_on_a_corridor(zigzag):
    maze = zigzag.unwrapped
    planner = NEXTPlanner.for_env(zigzag, SearchSettings(), TrainSettings(hidden=(64, 64)), seed=0)
    starts, goals = (x.astype(np.float64) for x in maze.tasks("train"))
    demos = [
        planner.search(s, g, guided=False, improve_iterations=200) for s, g in zip(starts, goals, strict=True)
    ]
    assert planner.imitate([r.path if r.solved else None for r in demos], goals) == 20
    losses = planner.train(2000)
    assert losses["policy_loss"] < 0.5 and losses["value_loss"] < 0.05
    test_starts, test_goals = (x.astype(np.float64) for x in maze.tasks("test"))
    checks = {}
    for guided in (False, True):  # the same search, the same noise; uniform: no model at all
        rng = np.random.default_rng(10)
        results = [
            planner.search(s, g, guided=guided, rng=rng) for s, g in zip(test_starts, test_goals, strict=True)
        ]
        assert all(r.solved for r in results)
        checks[guided] = sum(r.checks for r in results)
    assert checks[True] < 0.5 * checks[False], checks


def test_demonstrations_become_imitation_targets():
    env = make("maze-point", layout="u-maze")
    maze = env.unwrapped
    planner = NEXTPlanner.for_env(env, SearchSettings(), TrainSettings(hidden=(16,)), seed=0)
    starts, goals = (x.astype(np.float64)[:2] for x in maze.tasks("train"))
    paths, checks = rrt_star_demonstrations(env, starts, goals, 0.05, seed=0)
    assert checks > 0 and all(p is not None for p in paths)
    assert planner.imitate(paths, goals) == 2
    x, u, v = planner.data.arrays()
    assert len(x) == len(u) == len(v) > 0
    assert (np.linalg.norm(u, axis=1) <= 1 + 1e-5).all()  # a move of at most one step
    assert (v >= -1e-6).all() and v.max() * planner.space.diameter <= max(
        maze.goal_distance(p[:-1], p[1:]).sum() for p in paths
    ) + 2 * maze.success_radius
    env.close()


def _next_trial(**overrides):
    from copilot_ray.algorithms.next.config import NEXTConfig
    from copilot_ray.algorithms.next.trial import NEXTTrial

    values = {
        "demonstrator": "search",
        "num_demos": 4,
        "demo_train_steps": 30,
        "self_improve_rounds": 2,
        "tasks_per_round": 3,
        "round_train_steps": 20,
        "train_improve_iterations": 20,
        "eval_num_tasks": 3,
        "hidden": [16, 16],
        "max_iterations": 400,
        "rrt_reference_time_s": 0.05,
        **overrides,
    }
    cfg = NEXTConfig.from_settings(values, RunContext("maze-point", {"layout": "u-maze"}, seed=1))
    return NEXTTrial(config={"algorithm_config": cfg})


def test_a_restored_trial_continues_identically(tmp_path):
    trial = _next_trial()
    try:
        first = trial.train()
        assert not first.get("done") and first["paths"]["tasks"] == 3
        assert {"success_vs_rrt", "length_vs_rrt", "collision_checks_vs_rrt"} <= set(first["paths"])
        # Checks are the x axis (env steps): training so far (demonstrations included) + this evaluation.
        assert first["env_runners"]["num_env_steps_sampled_lifetime"] == first["paths"]["collision_checks"]
        assert first["paths"]["collision_checks"] > trial.planner.checks > 0
        trial.save_checkpoint(str(tmp_path))
        expected = [trial.train() for _ in range(2)]
        assert not expected[0].get("done") and expected[1]["done"]  # 1 + self_improve_rounds iterations
    finally:
        trial.stop()
    restored = _next_trial()
    try:
        restored.load_checkpoint(str(tmp_path))
        got = [restored.train() for _ in range(2)]
        assert [g["paths"] for g in got] == [e["paths"] for e in expected]  # model, data, noise: identical
    finally:
        restored.stop()


@pytest.mark.parametrize(
    ("key", "value", "why"),
    [
        ("step_length", 0, "step_length must be a number > 0"),
        ("uniform_share", 1.5, r"uniform_share must be a number in \[0, 1\]"),
        ("demonstrator", "ompl", r"demonstrator must be one of \['rrt_star', 'search'\]"),
        ("hidden", [], r"hidden must be a non-empty list"),
    ],
)
def test_bad_settings_are_refused_by_name(key, value, why):
    spec = {
        "name": "n",
        "env": {"id": "maze-point"},
        "algorithm": "next",
        "config": {key: value},
        "stop": {"iterations": 1},
    }
    with pytest.raises(SpecError, match=rf"config\.{key}: .* is invalid: {why}"):
        parse_spec(spec)
    assert parse_spec({**spec, "config": {}}).algorithm == "next"
