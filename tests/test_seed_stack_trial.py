"""`SeedStackTrial`: seeds of one configuration trained together in one trial (spec `seeds_per_trial`).

In-process, without Tune (on the session's Ray: building an RLlib algorithm puts its config there, and
would otherwise start a Ray of its own). With the updates stacked (a GPU's way, forced here on the CPU): a
stack of seeds {0, 1} gives seed 1 exactly what a stack of seed 1 alone gives it (its planner,
traversal, evaluation, actions and SAC updates: no draw of seed 0 leaks into it); a stack restored from
its checkpoint continues as the stack that wrote it; a seed whose planner goes non-finite stops alone,
named, while the other goes on. With each seed's own update (a CPU's way): seed 1 of a stack trains
exactly as its one-seed trial.
"""

from __future__ import annotations

import math

import pytest
import torch
import yaml
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray import keys
from copilot_ray.tracking import result_metrics
from copilot_ray.trials.seed_stack_trial import SeedStackTrial

SPEC = {
    "name": "stack",
    "env": {"id": "maze-point", "config": {"layout": "u-maze"}},
    "algorithm": "copilot",
    "config": {
        "tree_depth": 2,
        "repetitions": 1,
        "task_batch_size": 2,
        "tau_max": 8,
        "eval_interval": 1,
        "eval_num_tasks": 3,
        "eval_tree_tasks": 1,
        "num_steps_sampled_before_learning_starts": 40,
        "train_batch_size_per_learner": 16,
        "updates_per_env_step": 0.25,
        "cost_model.init_euclidean": 300,
        "cost_model.fit_steps": 3,
        "planner_warm_start": 2,
        "planner_task_batch_size": 4,
    },
    "seeds": [0, 1],
    "seeds_per_trial": 2,
    "searcher": {"type": "grid"},
    "stop": {"iterations": 3},
    "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
}
# What differs between two runs of the same seed only by the clock.
TIMING = ("time", "timers", "throughput", "duration", "_s", "sample", "connector", "weights_seq_no")


def _spec(tmp_path):
    path = tmp_path / "stack.yaml"
    path.write_text(yaml.safe_dump({**SPEC, "tracking": {"storage": str(tmp_path / "results")}}))
    return str(path)


def _trial(spec_path, seeds):
    return SeedStackTrial(config={keys.SPEC_PATH_KEY: spec_path, keys.SEEDS_KEY: list(seeds)})


@pytest.fixture
def stacked_updates(monkeypatch):
    """The stacked update and batched acting on this CPU (where a stack otherwise updates per seed)."""
    monkeypatch.setattr(SeedStackTrial, "stack_updates", True)


def _timing(key):
    return any(t in key for t in TIMING) or key == keys.TIME_TOTAL_S


def _figures(result, seed):
    """A seed's metrics that do not depend on the clock."""
    return {k: v for k, v in result[keys.SEED_RESULTS][str(seed)].items() if not _timing(k)}


def _assert_same(a, b, what):
    assert a.keys() == b.keys(), what
    for key in a:
        assert a[key] == pytest.approx(b[key], rel=1e-5, abs=1e-6, nan_ok=True), (what, key)


def _weights(trial, index):
    module = trial.stack.learners[index].module[DEFAULT_MODULE_ID]
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def test_a_stacked_seed_trains_as_it_would_alone_restores_exactly_and_fails_alone(
    ray_session, tmp_path, monkeypatch, stacked_updates
):
    from copilot_ray.algorithms.sac.stacked_updates import StackedAgentUpdates

    monkeypatch.setenv("COPILOT_RAY_FAULT", "planner_nan@3:seed=1")  # seed 1's planner breaks at iteration 3
    acting = []  # the seeds of every batched forward pass
    act = StackedAgentUpdates.act
    monkeypatch.setattr(StackedAgentUpdates, "act", lambda self, r: acting.append(sorted(r)) or act(self, r))
    spec = _spec(tmp_path)
    pair = _trial(spec, [0, 1])
    first = pair.train()
    assert [0, 1] in acting  # both seeds' env steps went through one forward pass
    # seed 0 as if 3 of its steps had gone non-finite, counted by the stack and logged by its learner:
    # a restored stack must not log them again (its learner's count starts anew)
    pair.stack.step.skipped[0] += 3
    pair.stack.learners[0].note_skipped_logged(int(pair.stack.step.skipped[0]))
    checkpoint = pair.save(str(tmp_path / "checkpoint"))
    second = pair.train()
    pair_weights = _weights(pair, 1)
    pair.stop()

    alone = _trial(spec, [1])
    for together in (first, second):
        _assert_same(_figures(together, 1), _figures(alone.train(), 1), "seed 1 in a pair vs alone")
    for key, value in _weights(alone, 0).items():
        torch.testing.assert_close(pair_weights[key], value, rtol=1e-5, atol=1e-6, msg=key)
    alone.stop()
    # the seeds differ (the comparison above could fail), and each did SAC updates
    assert _figures(second, 0) != _figures(second, 1)
    for seed in (0, 1):
        assert second[keys.SEED_RESULTS][str(seed)][keys.AGENT_SAC_UPDATES] > 0

    restored = _trial(spec, [0, 1])
    restored.restore(checkpoint)
    again = restored.train()
    for seed in (0, 1):
        _assert_same(_figures(second, seed), _figures(again, seed), f"seed {seed} after a restore")

    third = restored.train()  # iteration 3: seed 1's planner is NaN
    restored.stop()
    assert list(third[keys.SEED_ERRORS]) == ["1"]
    assert third[keys.SEED_ERRORS]["1"].startswith("NonFiniteStateError: iteration 3")
    assert third[keys.SEED_RESULTS]["0"][keys.TRAINING_ITERATION] == 3  # seed 0 went on
    assert third[keys.SEED_RESULTS]["1"][keys.TRAINING_ITERATION] == 2  # seed 1's last iteration
    assert third["done"]  # seed 0 reached the stop (3 iterations), seed 1 failed
    # what a searcher reads: the seeds still alive (seed 0 alone now)
    success = keys.validation_key(keys.EVAL_SUCCESS)
    assert (
        third[keys.ENV_STEPS.split("/")[0]][keys.ENV_STEPS.split("/")[1]]
        == third[keys.SEED_RESULTS]["0"][keys.ENV_STEPS]
    )
    top = third
    for part in success.split("/"):
        top = top[part]
    assert math.isclose(top, third[keys.SEED_RESULTS]["0"][success])


def test_a_stacked_her_seed_relabels_as_it_would_alone(ray_session, tmp_path, stacked_updates):
    """HER's relabelling buffer stacked: seed 1's hindsight goals, rewards and updates in a pair are its
    own (drawn from its generators), as in a stack of seed 1 alone."""
    her = {
        "name": "stack_her",
        "algorithm": "her",
        "config": {
            "tau_max": 12,
            "task_batch_size": 2,
            "eval_interval": 1,
            "eval_num_tasks": 3,
            "num_steps_sampled_before_learning_starts": 30,
            "train_batch_size_per_learner": 16,
            "updates_per_env_step": 0.25,
        },
    }
    path = tmp_path / "her.yaml"
    path.write_text(yaml.safe_dump({**SPEC, **her, "tracking": {"storage": str(tmp_path / "results")}}))
    pair, alone = _trial(str(path), [0, 1]), _trial(str(path), [1])
    assert pair.stack.hindsight
    for _ in range(2):
        together, own = pair.train(), alone.train()
        _assert_same(_figures(together, 1), _figures(own, 1), "HER seed 1 in a pair vs alone")
    assert own[keys.SEED_RESULTS]["1"][keys.AGENT_SAC_UPDATES] > 0
    assert _figures(together, 0) != _figures(together, 1)
    pair.stop()
    alone.stop()


def test_on_a_cpu_a_stacked_seed_trains_exactly_as_its_one_seed_trial(ray_session, tmp_path):
    """The CPU's default: no stacked update, each seed its own (in its turn, its own random state), so
    seed 1 of a pair is its one-seed trial, figure for figure."""
    from copilot_ray.algorithms.copilot.trial import CoPilotTrial

    spec = _spec(tmp_path)
    pair = _trial(spec, [0, 1])
    assert pair.stack is None
    own = CoPilotTrial(config={keys.SPEC_PATH_KEY: spec, keys.SEED_PARAM: 1})
    for _ in range(2):
        together, alone = pair.train(), own.train()
        figures = {k: v for k, v in result_metrics(alone, rllib_timers=True).items() if not _timing(k)}
        _assert_same(_figures(together, 1), figures, "seed 1 of a pair vs its one-seed trial")
    assert together[keys.SEED_RESULTS]["1"][keys.AGENT_SAC_UPDATES] > 0
    pair.stop()
    own.stop()
