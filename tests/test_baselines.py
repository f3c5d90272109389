"""The RL baselines (SAC, HER, SoRB, PPO) as RLlib algorithms and as sweep trials, on the open maze of
the demo: they report the common success metric, SoRB searches its graph, and they resume from checkpoints.
How well each learns the open maze is `benchmarks/baselines.py demo`'s figure."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml

from copilot_ray import keys

OPEN_MAZE = {"layout": "empty", "speed": 0.05, "success_radius": 0.1}


def _train(algo, iterations):
    results = [algo.train() for _ in range(iterations)]
    evaluated = [r for r in results if not np.isnan(keys.result_value(r, keys.EVAL_SUCCESS, np.nan))]
    return results, evaluated


def _her(**search):
    from copilot_ray.algorithms.sac.algorithm import HERConfig
    from copilot_ray.algorithms.sorb.algorithm import SoRBConfig

    cls = SoRBConfig if search else HERConfig
    config = (
        cls()
        .environment("maze-point", env_config=OPEN_MAZE)
        .agent(tau_max=40, task_batch_size=8, eval_interval=3, eval_num_tasks=40)
        .training(num_steps_sampled_before_learning_starts=500)
        .debugging(seed=0)
    )
    return config.search(**search) if search else config


@pytest.mark.parametrize("fused", [True, False], ids=["fused", "host_batches"])
def test_her_reports_the_common_metric_and_resumes_with_its_replay(ray_session, tmp_path, fused):
    """HER's evaluation is one rollout of its agent; a restored checkpoint has the same relabelling buffer
    and samples the same batches. Either update path trains from the one relabelling buffer (sampled in
    the fused step on the learner's device, or on the host for RLlib's `update(batch=...)`)."""
    algo = _her().agent(fused_update=fused).build_algo()
    try:
        results, evaluated = _train(algo, 3)
        last = evaluated[-1]
        assert 0.0 <= keys.result_value(last, keys.EVAL_SUCCESS) <= 1.0
        # no plan: the common figure, success_planned and success_direct are one rollout
        assert keys.result_value(last, keys.EVAL_SUCCESS) == keys.result_value(last, keys.SUCCESS_DIRECT)
        assert keys.result_value(last, keys.PATH_SUCCESS) is None  # [s0, g] is no path to score
        buffer = algo.agent_updater.buffer
        assert type(algo.agent_updater).__name__ == ("FusedLearnerUpdater" if fused else "FastLearnerUpdater")
        assert type(buffer).__name__ == "HindsightReplayBuffer" and buffer.n_sampled_goal == 4
        assert buffer.sampler.counters.tolist()[0] > 0  # the updates sampled it
        path = algo.save_to_path(str(tmp_path / "ckpt"))
        steps = keys.result_value(results[-1], keys.ENV_STEPS)
        from copilot_ray.algorithms.sac.algorithm import GoalSAC

        restored = GoalSAC.from_checkpoint(path)
        try:
            copy = restored.agent_updater.buffer
            assert len(copy) == len(buffer) and copy.num_added == buffer.num_added
            torch.manual_seed(0)
            a = buffer.sample(32)
            torch.manual_seed(0)
            b = copy.sample(32)
            for key in a:
                np.testing.assert_array_equal(a[key].cpu().numpy(), b[key].cpu().numpy())
            after = restored.train()
            assert keys.result_value(after, keys.ENV_STEPS) > steps  # continues the step count
        finally:
            restored.stop()
    finally:
        algo.stop()


PRETRAIN = 1000


def test_sorb_starts_later_then_searches_its_replay_graph(ray_session):
    """Before pre-training ends it is evaluated as its agent alone (no graph), on the same cadence as
    every method; afterwards the graph has edges, paths have waypoints and are what it follows, and the
    critic's step estimates grow with the distance."""
    algo = _her(pretrain_env_steps=PRETRAIN, graph_size=150, max_edge_steps=5, waypoint_steps=10).build_algo()
    try:
        results, evaluated = _train(algo, 6)
        early = [r for r in evaluated if keys.result_value(r, keys.ENV_STEPS) < PRETRAIN]
        assert early, "evaluated before its search starts"
        for r in early:  # the agent alone: no graph, the headline is the direct rollout
            assert np.isnan(keys.result_value(r, keys.SORB_GRAPH_EDGES, np.nan))
            assert keys.result_value(r, keys.EVAL_SUCCESS) == keys.result_value(r, keys.SUCCESS_DIRECT)
        last = evaluated[-1]
        assert keys.result_value(last, keys.SORB_GRAPH_EDGES) > 0
        assert keys.result_value(last, keys.SORB_WAYPOINTS) >= 2
        assert keys.result_value(last, keys.EVAL_SUCCESS) == keys.result_value(last, keys.SUCCESS_PLANNED)
        assert 0.0 <= keys.result_value(last, keys.PATH_SUCCESS) <= 1.0  # its waypoints, scored as a path
        # the edge weights: steps from Q grow with the distance to the goal (on average)
        rng = np.random.default_rng(0)
        starts = rng.uniform(0.1, 0.9, size=(200, 2)).astype(np.float32)
        direction = rng.standard_normal((200, 2))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        near = np.clip(starts + 0.1 * direction, 0.01, 0.99).astype(np.float32)
        far = np.clip(starts + 0.6 * direction, 0.01, 0.99).astype(np.float32)
        d_near, d_far = (algo.critic_distance(starts, starts, g) for g in (near, far))
        assert (d_near >= 1.0).all() and np.isfinite(d_far).all()
        assert d_far.mean() > d_near.mean() + 2
    finally:
        algo.stop()


def test_sorb_with_the_map_counts_every_edge_check_as_a_privilege(ray_session):
    """algorithm sorb_map: its graph's edges are checked against the map, each check counted in the
    privileges its iteration logs (after the evaluation that built the graph); plain SoRB counts none."""
    from copilot_ray.registry import RunContext, get_algorithm

    values = {
        "tau_max": 40,
        "task_batch_size": 4,
        "eval_num_tasks": 5,
        "sorb.pretrain_env_steps": 0,
        "sorb.graph_size": 30,
        # An untrained critic puts every pair ~1,400 steps apart: a cutoff above that keeps every edge.
        "sorb.max_edge_steps": 100_000,
        "num_steps_sampled_before_learning_starts": 10_000,  # wiring only: no SAC update
    }
    counts = {}
    for name in ("sorb_map", "sorb"):
        entry = get_algorithm(name)
        assert ("collision_checks" in entry.privileges(entry.defaults_as_logged())) == (name == "sorb_map")
        algo = entry.build_config(
            values, RunContext("maze-point", {"layout": "four-rooms"}, seed=0)
        ).build_algo()
        try:
            result = algo.train()
            assert keys.result_value(result, keys.SORB_GRAPH_EDGES) >= 0
            counts[name] = (
                keys.result_value(result, keys.PRIVILEGE_COLLISION_CHECKS),
                algo._collision_checks(),
            )
        finally:
            algo.stop()
    checks, counted = counts["sorb_map"]
    assert checks == counted >= 30 * 29  # every node pair at least, then the tasks' own edges
    assert counts["sorb"] == (0, 0)


def test_ppo_reports_the_common_metric_and_resumes(ray_session, tmp_path):
    from copilot_ray.algorithms.ppo.algorithm import GoalPPO, GoalPPOConfig

    config = (
        GoalPPOConfig()
        .environment("maze-point", env_config=OPEN_MAZE)
        .goal_task(tau_max=40, eval_interval=1, eval_num_tasks=20)
        .training(train_batch_size_per_learner=400, minibatch_size=100, num_epochs=2)
        .debugging(seed=0)
    )
    algo = config.build_algo()
    try:
        result = algo.train()
        assert keys.result_value(result, keys.ENV_STEPS) >= 400
        success = keys.result_value(result, keys.EVAL_SUCCESS)
        assert 0.0 <= success <= 1.0 and success == keys.result_value(result, keys.SUCCESS_DIRECT)
        sampled = keys.result_value(result, keys.eval_by_action(keys.SUCCESS_DIRECT, "sampled"))
        assert 0.0 <= sampled <= 1.0
        path = algo.save_to_path(str(tmp_path / "ppo"))
    finally:
        algo.stop()
    restored = GoalPPO.from_checkpoint(path)
    try:
        assert keys.result_value(restored.train(), keys.ENV_STEPS) >= 800
    finally:
        restored.stop()


@pytest.mark.parametrize(
    "kind, setting, value, why",
    [
        ("her", "her.n_sampled_goal", 0, "an integer >= 1"),
        ("her", "her.goal_selection", "later", "one of"),
        ("sorb", "sorb.max_edge_steps", 0, "an integer >= 1"),
        ("ppo", "minibatch_size", 0, "an integer >= 1"),
    ],
)
def test_bad_baseline_settings_are_refused_before_anything_runs(tmp_path, kind, setting, value, why):
    from copilot_ray.sweep_spec import SpecError, load_spec

    spec = {
        "name": "bad",
        "env": {"id": "maze-point", "config": OPEN_MAZE},
        "algorithm": kind,
        "config": {setting: value},
        "seeds": [0],
        "stop": {"env_steps": 100, "min_evaluations": 1},
    }
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(SpecError) as err:
        load_spec(path)
    assert f"config.{setting}" in str(err.value) and repr(value) in str(err.value) and why in str(err.value)


def test_a_baselines_spec_file_runs_every_algorithm_into_one_experiment(ray_session, tmp_path, capsys):
    """sorb and ppo from one several-spec file through Tune and MLflow: every trial's run is FINISHED
    with copilot/eval/success logged against env steps. (sac and her share one trial class, her with
    another replay; tests/test_fair_comparison.py runs her through Tune, privileges included.)"""
    import mlflow

    from copilot_ray.keys import ALGORITHM_TAG, ROLE_TAG, ROLE_TRIAL
    from copilot_ray.sweep import main
    from copilot_ray.sweep_spec import load_specs

    common = {
        "experiment": "baselines",
        "env": {"id": "maze-point", "config": OPEN_MAZE},
        "seeds": [0],
        "resources": {"max_concurrent_trials": 2, "num_env_runners": 0},
        "tracking": {"storage": str(tmp_path / "results"), "uri": f"sqlite:///{tmp_path}/baselines.db"},
    }
    # one experiment is a comparison: one env-step cadence (every iteration passes a multiple of 1 step)
    agent = {"tau_max": 20, "task_batch_size": 4, "eval_every_env_steps": 1, "eval_num_tasks": 10}
    learning = {"num_steps_sampled_before_learning_starts": 100}
    parts = [
        {
            "name": "b_sorb",
            "algorithm": "sorb",
            "config": {**agent, **learning, "sorb.pretrain_env_steps": 0, "sorb.graph_size": 50},
            "stop": {"iterations": 2, "min_evaluations": 1},
        },
        {
            "name": "b_ppo",
            "algorithm": "ppo",
            "config": {
                **{k: v for k, v in agent.items() if k != "task_batch_size"},
                "train_batch_size_per_learner": 200,
                "minibatch_size": 100,
                "num_epochs": 1,
            },
            "stop": {"iterations": 2, "min_evaluations": 1},
        },
    ]
    path = tmp_path / "baselines.yaml"
    path.write_text("---\n".join(yaml.safe_dump({**p, **common}, sort_keys=False) for p in parts))
    assert main([str(path)]) == 0
    out = capsys.readouterr().out
    assert "sorb on maze-point" in out and "ppo on maze-point" in out  # progress lines name them

    spec = load_specs(path)[0]
    client = mlflow.MlflowClient(spec.tracking.uri)
    exp = client.get_experiment_by_name("baselines")
    runs = [
        r
        for r in client.search_runs([exp.experiment_id], max_results=100)
        if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL
    ]
    assert sorted(r.data.tags[ALGORITHM_TAG] for r in runs) == ["ppo", "sorb"]
    for run in runs:
        assert run.info.status == "FINISHED"
        # agents that learn from their own episodes alone: no privilege, every count 0
        assert run.data.tags[keys.PRIVILEGES_TAG] == "none"
        for key in keys.PRIVILEGE_COUNTS:
            assert [m.value for m in client.get_metric_history(run.info.run_id, key)] == [0.0, 0.0], key
        history = client.get_metric_history(run.info.run_id, keys.EVAL_SUCCESS)
        assert len(history) == 2 and all(0.0 <= m.value <= 1.0 for m in history)
        assert history[1].step > history[0].step > 0  # MLflow steps are env steps
        if run.data.tags[ALGORITHM_TAG] == "sorb":  # its graph's figures reach MLflow too
            assert len(client.get_metric_history(run.info.run_id, keys.SORB_WAYPOINTS)) == 2
