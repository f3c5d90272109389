"""Planners scored as motion planners (paths/*, the paper's Fig. 4b/4c) and the planner-only baselines'
trials (RRT*, SGT-PG) run directly, without a Ray cluster."""

from __future__ import annotations

import numpy as np
import pytest

from copilot_ray import keys
from copilot_ray.envs import make
from copilot_ray.planning import path_metrics as pm
from copilot_ray.registry import RunContext


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("COPILOT_RAY_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "rrt_reference"


@pytest.fixture(scope="module")
def four_rooms():
    env = make("maze-point", layout="four-rooms")
    yield env
    env.close()


def test_score_paths_needs_every_segment_free_and_the_goal_reached(four_rooms):
    maze = four_rooms.unwrapped
    starts, goals = maze.tasks("test")
    through = np.stack([starts, goals], axis=1)
    blocked = maze.segments_collide(starts, goals)
    assert blocked.any() and not blocked.all()
    scores = pm.score_paths(maze, through, goals)
    # A straight line succeeds exactly when the motion check finds it free; its length is the distance.
    assert (scores.success == ~blocked).all()
    free = ~blocked
    np.testing.assert_allclose(scores.length[free], maze.goal_distance(starts[free], goals[free]))
    assert np.isinf(scores.length[blocked]).all()
    # Free but stopping short of the goal radius: not a success.
    short = through[free][:3].copy()
    short[:, -1] = short[:, 0] + 0.5 * (short[:, 1] - short[:, 0])
    assert not pm.score_paths(maze, short, goals[free][:3]).success.any()


def test_path_metrics_divide_by_rrt_on_the_same_tasks():
    scores = pm.PathScores(np.array([True, True, False, True]), np.array([2.0, 3.0, np.inf, 1.0]))
    reference = pm.RRTReference(
        np.array([True, True, True, False, True]),  # one more task than scored: only the first 4 count
        np.array([1.0, 2.0, 1.0, np.inf, 9.0]),
        np.array([10, 20, 30, 40, 1000]),
    )
    got = pm.path_metrics(scores, collision_checks=50, reference=reference)
    assert got[keys.PATH_SUCCESS] == 0.75 and got[keys.PATH_TASKS] == 4
    assert got[keys.PATH_LENGTH] == pytest.approx(2.0)
    assert got[keys.PATH_SUCCESS_VS_RRT] == pytest.approx(0.75 / 0.75)
    assert got[keys.PATH_LENGTH_VS_RRT] == pytest.approx((2.0 + 1.5) / 2)  # tasks 0, 1: both solved
    assert got[keys.PATH_CHECKS_VS_RRT] == pytest.approx(50 / 100)
    alone = pm.path_metrics(scores, 50)
    assert keys.PATH_LENGTH_VS_RRT not in alone and alone[keys.PATH_COLLISION_CHECKS] == 50
    with pytest.raises(ValueError, match="covers 2 tasks, 4 were scored"):
        pm.path_metrics(
            scores,
            1,
            pm.RRTReference(*(a[:2] for a in (reference.solved, reference.length, reference.checks))),
        )


def test_rrt_reference_is_computed_once_and_cached(cache, monkeypatch):
    first = pm.rrt_reference("maze-point", {"layout": "u-maze"}, 3, 0.05, seed=0)
    assert first.solved.all() and (first.checks > 0).all() and np.isfinite(first.length).all()
    assert len(list(cache.glob("maze-point-3tasks-*.npz"))) == 1

    def no_planning(*args, **kwargs):
        raise AssertionError("planned again instead of reading the cache")

    monkeypatch.setattr(pm, "plan_rrt_star", no_planning)
    again = pm.rrt_reference("maze-point", {"layout": "u-maze"}, 3, 0.05, seed=0)
    np.testing.assert_array_equal(again.length, first.length)
    with pytest.raises(AssertionError, match="planned again"):  # other settings: another reference
        pm.rrt_reference("maze-point", {"layout": "u-maze"}, 3, 0.1, seed=0)


def _sgt_pg_trial(**overrides):
    from copilot_ray.algorithms.sgt_pg.config import SGTPGConfig
    from copilot_ray.algorithms.sgt_pg.trial import SGTPGTrial

    values = {
        "tree_depth": 3,
        "phases_per_iteration": 3,
        "eval_num_tasks": 8,
        "task_batch_size": 6,
        "planner.num_samples": 4,
        "rrt_reference_time_s": 0.05,
        **overrides,
    }
    cfg = SGTPGConfig.from_settings(values, RunContext("maze-point", {"layout": "u-maze"}, seed=1))
    return SGTPGTrial(config={"algorithm_config": cfg})


def test_sgt_pg_trial_logs_paths_against_rrt_and_resumes_exactly(cache, tmp_path):
    trial = _sgt_pg_trial()
    try:
        results = [trial.train() for _ in range(2)]
        checks = [r["paths"]["collision_checks"] for r in results]
        # Checks are the x axis: reported as env steps, growing with every phase.
        assert [r["env_runners"]["num_env_steps_sampled_lifetime"] for r in results] == checks
        assert 0 < checks[0] < checks[1] == trial.checks.count
        assert results[-1]["paths"]["planner_updates"] == 6
        for key in keys.PATH_METRICS:
            assert key.split("/")[1] in results[-1]["paths"], key
        assert len(list(cache.glob("maze-point-8tasks-*.npz"))) == 1
        saved = trial.save(str(tmp_path / "ckpt"))  # what Tune does, and restore() below when it retries
        expected = trial.train()
    finally:
        trial.stop()
    restored = _sgt_pg_trial()
    try:
        restored.restore(saved)
        assert restored.training_iteration == 2
        got = restored.train()
        assert got["paths"] == expected["paths"]  # same planner, optimizer, task sampler and noise
    finally:
        restored.stop()


def test_rrt_star_trial_plans_in_chunks_ends_and_stores_the_reference(cache, tmp_path):
    from copilot_ray.algorithms.rrt_star.config import RRTStarConfig
    from copilot_ray.algorithms.rrt_star.trial import RRTStarTrial

    values = {"time_limit_s": 0.1, "eval_num_tasks": 5, "tasks_per_iteration": 2}
    cfg = RRTStarConfig.from_settings(values, RunContext("maze-rigid", {"layout": "u-maze"}, seed=0))
    trial = RRTStarTrial(config={"algorithm_config": cfg})
    try:
        first = trial.train()
        assert first["paths"]["tasks"] == 2 and not first.get("done")
        saved = trial.save(str(tmp_path / "ckpt"))
        results = [trial.train() for _ in range(2)]
        assert [r["paths"]["tasks"] for r in results] == [4, 5] and results[-1]["done"]
        figures = results[-1]["paths"]
        assert figures["success"] > 0  # RRT* is its own reference:
        assert (
            figures["success_vs_rrt"] == figures["length_vs_rrt"] == figures["collision_checks_vs_rrt"] == 1
        )
        stored = pm.RRTReference.load(pm.reference_path("maze-rigid", {"layout": "u-maze"}, 5, 0.1, 0))
        assert stored.checks.sum() == results[-1]["paths"]["collision_checks"]
    finally:
        trial.stop()
    restored = RRTStarTrial(config={"algorithm_config": cfg})
    try:
        restored.restore(saved)  # Tune's call when it retries or resumes the trial
        assert restored.train()["paths"]["tasks"] == 4  # continues after the 2 planned tasks
    finally:
        restored.stop()
