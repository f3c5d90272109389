"""CoPilot on a local two-core Ray: a tiny run, its metrics, and a checkpoint round trip."""

from pathlib import Path

import numpy as np
import pytest
import torch

from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig

pytestmark = pytest.mark.ray


def tiny_config(
    fast_learner: bool = True, num_env_runners: int = 1, collision_cost="indicator", rrt_reference_s=0.0
) -> CoPilotConfig:
    return (
        CoPilotConfig()
        .environment("maze-point", env_config={"layout": "u-maze"})
        .env_runners(num_env_runners=num_env_runners)
        .training(num_steps_sampled_before_learning_starts=50, train_batch_size_per_learner=32)
        .debugging(seed=3)
        .copilot(
            tree_depth=2,
            repetitions=2,
            task_batch_size=3,
            tau_max=8,
            eval_num_tasks=4,
            eval_tree_tasks=2,
            updates_per_env_step=0.05,
            fast_learner=fast_learner,
            collision_cost=collision_cost,
            planner={"num_samples": 4, "std_anneal_phases": 6},
            cost_model={"init_euclidean": 500, "fit_steps": 5},
            planner_warm_start=3,
            planner_task_batch_size=5,
            eval_rrt_reference_s=rrt_reference_s,
        )
    )


EXPECTED_METRICS = [
    ("copilot", "eval", "success_planned"),
    ("copilot", "eval", "success_direct"),
    ("copilot", "eval", "success_auc"),
    # the same headline figures on the validation tasks (what searchers read)
    ("copilot", "validation", "success"),
    ("copilot", "validation", "success_planned"),
    ("copilot", "validation", "success_direct"),
    ("copilot", "validation", "success_auc"),
    ("copilot", "validation", "return"),
    # privileges used so far: the planner's collision checks, the restart resets and map queries
    ("copilot", "privileges", "collision_checks"),
    ("copilot", "privileges", "resets"),
    ("copilot", "privileges", "map_queries"),
    ("copilot", "alpha"),
    ("copilot", "planner", "cost_layer_0"),
    ("copilot", "planner", "cost_layer_2"),
    ("copilot", "planner", "approx_kl_max"),
    ("copilot", "planner", "nonfinite_skipped"),
    # how well tau_hat tracks the agent's time costs (the new sub-tasks, before its refit)
    ("copilot", "diag", "tau_hat_error_steps"),
    ("copilot", "diag", "euclidean_error_steps"),
    ("copilot", "agent", "steps_layer_0"),
    ("copilot", "agent", "steps_layer_2"),
    ("copilot", "agent", "success_layer_1"),
    ("copilot", "dtau", "size"),
    ("copilot", "cost_model", "loss"),
    ("copilot", "eval", "deterministic", "success_planned"),
    ("copilot", "eval", "sampled", "success_planned"),
    ("copilot", "eval", "sampled", "reached_direct"),
    ("copilot", "eval", "deterministic", "subgoals_reached_planned"),
    ("copilot", "diag", "subgoal_in_obstacle_layer_2"),
    ("copilot", "diag", "segment_unreachable_layer_1"),
    ("copilot", "diag", "reachable_length_layer_2"),
    ("copilot", "diag", "dtau_tuple_length_mean"),
    ("copilot", "diag", "q_mean"),
    ("copilot", "planner", "std"),
    ("paths", "success"),
    ("paths", "collision_checks"),
    ("env_runners", "num_env_steps_sampled_lifetime"),
]
VS_RRT = [("paths", "success_vs_rrt"), ("paths", "collision_checks_vs_rrt")]


def lookup(result, key):
    for part in key:
        result = result[part]
    return result


@pytest.mark.parametrize("fast_learner", [True, False], ids=["fast", "stock"])
def test_two_iterations_log_metrics_and_checkpoint_round_trips(
    ray_session, tmp_path, monkeypatch, fast_learner
):
    # The stock run also covers the graded (length-in-collision) planner cost end to end, the fast one the
    # paths' figures against an RRT* reference (computed into a fresh cache). Both sample in the
    # algorithm's own process, as the sweeps run (a remote env runner: the env-runner-dying test below;
    # starting one costs ~10 s, twice here with the restored copy).
    collision_cost = "indicator" if fast_learner else "length"
    rrt_s = 0.05 if fast_learner else 0.0
    runners = 0
    monkeypatch.setenv("COPILOT_RAY_CACHE", str(tmp_path / "cache"))
    algo = tiny_config(
        fast_learner, runners, collision_cost=collision_cost, rrt_reference_s=rrt_s
    ).build_algo()
    try:
        results = [algo.train() for _ in range(2)]
        assert algo.curriculum.planner.max_grad_norm == 0.5  # CO-PILOT's default planner gradient clip
        # 3 warm-start phases, then one phase per repetition; the std annealed 0.05 -> 0.015 over 6.
        assert algo.curriculum.phases.count == 3 + 2 * 2
        assert algo.curriculum.planner.std[0] == pytest.approx(0.015)
        assert lookup(results[0], ("copilot", "planner", "warm_start_s")) > 0
        # The headline metrics are the deterministic ones (eval_action's default).
        assert lookup(results[-1], ("copilot", "eval", "success_planned")) == lookup(
            results[-1], ("copilot", "eval", "deterministic", "success_planned")
        )
        for key in EXPECTED_METRICS:
            assert np.isfinite(lookup(results[-1], key)), key
        # Fig. 4c's checks: every segment the planner's cost asked about (at least one phase's
        # 5 tasks x 4 sampled trees x 7 segments).
        checks = [lookup(r, ("paths", "collision_checks")) for r in results]
        assert 5 * 4 * 7 <= checks[0] < checks[1] == algo.curriculum.collision_checks
        assert [lookup(r, ("copilot", "privileges", "collision_checks")) for r in results] == checks
        # validation tasks are not test tasks: the sub-goal trees and per-action figures are test-only
        assert "deterministic" not in results[-1]["copilot"]["validation"]
        assert ("success_vs_rrt" in results[-1]["paths"]) == fast_learner
        if fast_learner:
            assert len(list((tmp_path / "cache" / "rrt_reference").glob("maze-point-4tasks-*.npz"))) == 1
            assert lookup(results[-1], VS_RRT[1]) > 0
        steps = [lookup(r, EXPECTED_METRICS[-1]) for r in results]
        # 3 tasks x 2 repetitions x (4 + 2 + 1) sub-tasks of at most 8 steps each, per iteration.
        assert 0 < steps[0] < steps[1] <= 2 * 3 * 2 * 7 * 8
        # D_tau: the 500 Euclidean tuples plus one per sub-task.
        assert lookup(results[-1], ("copilot", "dtau", "size")) == 500 + 2 * 2 * 3 * 7
        assert lookup(results[-1], ("learners", "default_policy", "num_module_steps_trained_lifetime")) > 0
        # The schedule ran 4 episodes (paper_per_task over b = 2: 0.9, 0.1, 0.9, 0.1).
        assert algo.curriculum.alpha_clock.episode == 4
        assert lookup(results[-1], ("copilot", "alpha")) == pytest.approx(0.5)
        artefacts = sorted((Path(algo.logdir) / "copilot_trees").glob("*.npz"))
        assert len(artefacts) == 2
        with np.load(artefacts[-1]) as art:
            assert art["trees"].shape == (2, 5, 2)
            assert art["tau_hat"].shape == art["tau_hat_length"].shape == (6,)
            assert art["subtask_steps"].shape == (2, 3, 4)
            assert (art["subtask_steps"][:, 0, 0] > 0).all() and (art["subtask_steps"][:, 0, 1:] == -1).all()

        path = algo.save_to_path(str(tmp_path / "ckpt"))
        restored = tiny_config(fast_learner, runners, collision_cost=collision_cost).build_algo()
        try:
            restored.restore_from_path(path)
            want, got = (
                algo.curriculum.planner.state_dict()["nets"],
                restored.curriculum.planner.state_dict()["nets"],
            )
            for name in want:
                torch.testing.assert_close(want[name], got[name])
            assert len(restored.curriculum.cost_model.dataset) == len(algo.curriculum.cost_model.dataset)
            assert restored.curriculum.alpha_clock.episode == algo.curriculum.alpha_clock.episode
            assert restored._rng.bit_generator.state == algo._rng.bit_generator.state
            assert restored.iteration == algo.iteration == 2
            assert restored.gradient_steps.get_state() == algo.gradient_steps.get_state()
            assert (
                restored.curriculum.phases.count == algo.curriculum.phases.count
                and restored.curriculum._warm_started
            )
            assert restored.curriculum.collision_checks == algo.curriculum.collision_checks
            assert restored.curriculum.planner.std.tolist() == algo.curriculum.planner.std.tolist()
            # The task sampler continues where it stopped: both draw the same next mini-batch.
            assert (restored._rng.integers(1 << 30, size=4) == algo._rng.integers(1 << 30, size=4)).all()
            if fast_learner:
                assert len(restored.agent_updater.buffer) == len(algo.agent_updater.buffer) > 0
            # the lean loop's exploration noise goes on from where it stopped
            runners = [a.env_runner_group.local_env_runner for a in (algo, restored)]
            if hasattr(runners[0], "action_noise"):
                assert torch.equal(runners[0].action_noise.get_state(), runners[1].action_noise.get_state())
            result = restored.train()
            assert lookup(result, EXPECTED_METRICS[-1]) > steps[-1]
        finally:
            restored.stop()
    finally:
        algo.stop()


def test_the_last_iteration_ends_at_the_repetition_that_reaches_the_budget(ray_session):
    """With an env-step budget the iteration that reaches it stops after that repetition (here the
    first of b = 2): a method with long iterations does not run far past a shared budget. The budget
    comes from the run (a sweep's stop.env_steps, train's --stop-env-steps)."""
    from copilot_ray.registry import RunContext
    from copilot_ray.sweep_spec import build_algorithm_config, parse_spec

    assert CoPilotConfig.from_settings({}, RunContext("maze-point", env_step_budget=7)).env_step_budget == 7
    spec = parse_spec(
        {
            "name": "budget",
            "env": {"id": "maze-point"},
            "algorithm": "copilot",
            "seeds": [0],
            "stop": {"env_steps": 1234, "min_evaluations": 1},
            "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
        },
        "budget.yaml",
    )
    assert build_algorithm_config({}, spec).env_step_budget == 1234

    steps, phases = {}, {}
    for budget in (None, 1):
        config = tiny_config(num_env_runners=0)
        config.env_step_budget = budget
        algo = config.build_algo()
        try:
            algo.train()
            steps[budget], phases[budget] = algo._env_steps(), algo.curriculum.phases.count
        finally:
            algo.stop()
    assert phases == {None: 3 + 2, 1: 3 + 1}  # warm start, then one planner phase per repetition
    assert 1 <= steps[1] < steps[None]  # the same seed: the first repetition alone


def _recording_planned_tasks(algo) -> list[tuple[int, ...]]:
    """The training tasks of every planner phase from now on (the batch each repetition plans for)."""
    seen, trees = [], algo.curriculum.trees

    def recording(starts, *args):
        seen.append(tuple(int(i) for i in algo._batch))
        assert len(starts) == len(algo._batch)  # the curriculum is given the whole batch
        return trees(starts, *args)

    algo.curriculum.trees = recording
    return seen


def test_an_iteration_ends_at_the_repetition_past_an_evaluation_point_and_the_next_resumes_the_batch(
    ray_session, tmp_path
):
    """With eval_every_env_steps below one repetition's env steps, each iteration is one repetition of
    b = 2 and one evaluation (the cadence the short-iteration baselines get); the batch's second
    repetition comes next iteration, also after a checkpoint round trip, on the same tasks, with the
    alpha schedule in phase; only then is a new batch drawn."""
    env_steps = EXPECTED_METRICS[-1]
    algo = tiny_config(num_env_runners=0).copilot(eval_every_env_steps=1).build_algo()
    try:
        seen = _recording_planned_tasks(algo)
        results = [algo.train()]
        assert (algo.curriculum.alpha_clock.episode, algo._batch_done) == (1, 1)
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        results += [algo.train(), algo.train()]
        assert seen[0] == seen[1] != seen[2]  # the batch's two repetitions, then a new draw
        assert (algo.curriculum.alpha_clock.episode, algo._batch_done) == (3, 1)
        # One evaluation per iteration, at the env steps where that iteration ended.
        assert algo.evaluation.curves["test"].steps == [float(lookup(r, env_steps)) for r in results]

        restored = tiny_config(num_env_runners=0).copilot(eval_every_env_steps=1).build_algo()
        try:
            restored.restore_from_path(path)
            assert restored._batch_done == 1 and tuple(restored._batch.tolist()) == seen[0]
            restored_seen = _recording_planned_tasks(restored)
            restored.train()
            assert restored_seen == [seen[0]] and restored._batch is None
            assert restored.curriculum.alpha_clock.episode == 2
        finally:
            restored.stop()
    finally:
        algo.stop()


def test_non_finite_planner_weights_stop_the_run_naming_them(ray_session, monkeypatch):
    from copilot_ray.planning.health import FAULT_ENV, NonFiniteStateError

    monkeypatch.setenv(FAULT_ENV, "planner_nan@2")  # the fault drill's hook: NaN at iteration 2's start
    algo = tiny_config(num_env_runners=0).build_algo()
    try:
        algo.train()
        with pytest.raises(
            NonFiniteStateError, match=r"iteration 2: non-finite \(NaN or inf\) weights in the planner"
        ):
            algo.train()
    finally:
        algo.stop()


def test_an_env_runner_dying_mid_iteration_loses_its_subtasks_countably_and_comes_back(ray_session):
    import ray

    algo = tiny_config(num_env_runners=1).copilot(subtasks_per_sample=2).build_algo()
    try:
        first = algo.train()
        assert lookup(first, ("copilot", "agent", "subtasks_lost")) == 0
        for key in EXPECTED_METRICS:  # every figure comes back from a remote env runner too
            assert np.isfinite(lookup(first, key)), key
        learn, killed = algo._learn, []

        def learn_then_kill(episodes):  # after the first sampling round of iteration 2
            learn(episodes)
            if not killed:
                (actor,) = algo.env_runner_group._worker_manager._actors.values()
                ray.kill(actor, no_restart=False)  # as if its process died: Ray restarts it
                killed.append(actor)

        algo._learn = learn_then_kill
        second = algo.train()  # goes on without the runner's remaining sub-tasks
        algo._learn = learn
        lost = lookup(second, ("copilot", "agent", "subtasks_lost"))
        # 3 tasks x 2 repetitions x 7 sub-tasks per tree; at most 2 of the first repetition were sampled
        assert 0 < lost <= 3 * 2 * 7 - 2
        third = algo.train()  # RLlib restored the runner before this iteration
        assert lookup(third, ("copilot", "agent", "subtasks_lost")) == 0
        assert algo.env_runner_group.num_healthy_remote_env_runners() == 1
        steps = [lookup(r, EXPECTED_METRICS[-1]) for r in (first, second, third)]
        assert steps[0] < steps[1] < steps[2]
    finally:
        algo.stop()


def _planner_weights(algo) -> list[np.ndarray]:
    return [p.detach().clone().numpy() for p in algo.curriculum.planner.parameters()]


def _recording_plan_sizes(algo) -> list[int]:
    """The number of tasks every planner phase plans from now on."""
    sizes, run = [], algo.curriculum.phases.run

    def recording(starts, *args, **kwargs):
        sizes.append(len(starts))
        return run(starts, *args, **kwargs)

    algo.curriculum.phases.run = recording
    return sizes


def test_a_frozen_planner_learns_nothing_after_its_warm_start_and_plans_only_the_agents_tasks(ray_session):
    """The co-training ablation (planner_frozen): after the warm start the planner's weights stay as they
    were while the default's move; its phases plan the agent's tasks only (task_batch_size, not the
    planner's batch of planner_task_batch_size) and count their collision checks."""
    moved = {}
    for frozen in (False, True):
        algo = tiny_config(num_env_runners=0).copilot(planner_frozen=frozen).build_algo()
        try:
            algo.curriculum.prepare(1, algo._rng)
            before, checks = _planner_weights(algo), algo._collision_checks()
            planned = _recording_plan_sizes(algo)
            algo.train()
            after = _planner_weights(algo)
            moved[frozen] = any(not np.array_equal(a, b) for a, b in zip(before, after, strict=True))
            assert algo._collision_checks() > checks  # the output trees' costs still ask the map
            assert planned == [3 if frozen else 5] * 2
        finally:
            algo.stop()
    assert moved == {False: True, True: False}
