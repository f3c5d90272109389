"""`SeedStackTrial`: seeds of one configuration trained together in one trial (spec `seeds_per_trial`).

In-process, without Tune (on the session's Ray: building an RLlib algorithm puts its config there, and
would otherwise start a Ray of its own). A stack of seeds {0, 1} gives seed 1 exactly what a stack of
seed 1 alone gives it (its planner, traversal, evaluation, actions and SAC updates: no draw of seed 0
leaks into it); a stack restored from its checkpoint continues as the stack that wrote it; a seed whose
planner goes non-finite stops alone, named, while the other goes on; a stack of three seeds trains each
exactly as its one-seed trial (CO-PILOT and HER); on a faked CUDA device its update is captured.
"""

from __future__ import annotations

import math

import pytest
import torch
import yaml
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray import keys
from copilot_ray.algorithms.sac.trial import SeedStackTrial
from copilot_ray.tracking import result_metrics

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
    module = trial.stack.updates.learners[index].module[DEFAULT_MODULE_ID]
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def test_a_stacked_seed_trains_as_it_would_alone_restores_exactly_and_fails_alone(
    ray_session, tmp_path, monkeypatch
):
    from copilot_ray.algorithms.sac.seed_stack import SeedStack

    monkeypatch.setenv("COPILOT_RAY_FAULT", "planner_nan@3:seed=1")  # seed 1's planner breaks at iteration 3
    acting = []  # the seeds of every batched forward pass
    act = SeedStack._act
    monkeypatch.setattr(
        SeedStack, "_act", lambda self, ids, obs: acting.append(list(ids)) or act(self, ids, obs)
    )
    spec = _spec(tmp_path)
    pair = _trial(spec, [0, 1])
    first = pair.train()
    assert [0, 1] in acting  # both seeds' env steps went through one forward pass
    # seed 0 as if 3 of its steps had gone non-finite, counted by the stack and logged by its learner:
    # a restored stack must not log them again (its learner's count starts anew)
    pair.stack.updates.step.skipped[0] += 3
    pair.stack.updates._skipped_logged[0] += 3
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


HER = {
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


def _learner_weights(algo):
    return _module_weights(algo.learner_group._learner.module[DEFAULT_MODULE_ID])


def _module_weights(module):
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


@pytest.mark.parametrize("algorithm", ["copilot", "her"])
def test_a_stack_of_three_seeds_trains_each_as_its_one_seed_trial(ray_session, tmp_path, algorithm):
    """Seeds {0, 1, 2} in one stack (their env steps in one loop, one batched act and one stacked update,
    HER relabelling in its stacked buffer) against each seed's own one-seed trial, over two
    iterations: every clock-free figure of every seed, and its learner's weights."""
    from copilot_ray.registry import get_algorithm

    data = {**SPEC, **(HER if algorithm == "her" else {}), "seeds": [0, 1, 2], "seeds_per_trial": 3}
    path = tmp_path / "three.yaml"
    path.write_text(yaml.safe_dump({**data, "tracking": {"storage": str(tmp_path / "results")}}))
    stack = _trial(str(path), [0, 1, 2])
    assert stack.stack._move is not None  # the maze: every env step moves all seeds' agents at once
    trial_class = get_algorithm(algorithm).trial_class()
    alone = [trial_class(config={keys.SPEC_PATH_KEY: str(path), keys.SEED_PARAM: s}) for s in (0, 1, 2)]
    for _ in range(2):
        together = stack.train()
        for seed, own in enumerate(alone):
            mine = {k: v for k, v in result_metrics(own.train(), rllib_timers=True).items() if not _timing(k)}
            _assert_same(_figures(together, seed), mine, f"seed {seed} of three vs its one-seed trial")
    for seed, own in enumerate(alone):
        want = _learner_weights(own)
        for key, value in _learner_weights(stack.algos[seed]).items():
            torch.testing.assert_close(value, want[key], rtol=1e-5, atol=1e-6, msg=f"seed {seed}: {key}")
        # the module its evaluation acts with (its env runner's): synced as the one-seed trial's is
        evaluated = _module_weights(own.get_module())
        for key, value in _module_weights(stack.algos[seed].get_module()).items():
            torch.testing.assert_close(value, evaluated[key], rtol=1e-5, atol=1e-6, msg=f"seed {seed}: {key}")
        assert together[keys.SEED_RESULTS][str(seed)][keys.AGENT_SAC_UPDATES] > 0
        # its replay is its ring of the stack's: as full as its one-seed twin's, and updated by the stack
        assert stack.algos[seed].agent_updater.replay_size() == own.agent_updater.replay_size() > 0
        with pytest.raises(RuntimeError, match="updated by its stack"):
            stack.algos[seed].agent_updater.update(1, {})
        own.stop()
    assert _figures(together, 0) != _figures(together, 1)  # the seeds differ: the comparison could fail
    stack.stop()


def test_on_a_faked_cuda_device_a_stacks_update_reaches_the_capture_site(ray_session, tmp_path, monkeypatch):
    """A stacked trial's update goes through the capture site every SAC update goes through
    (`sac_step.replay_step_call`), without a host sync; on a (faked) CUDA device it is a `CapturedCall` of the stacked step,
    warmed up and captured with the seeds' noise and sampling counters and the `active` mask in place,
    which every replay reads."""
    from copilot_ray.algorithms.gc_sac.graph_capture import CapturedCall
    from tests.test_graph_capture import Recorder
    from tests.test_no_host_sync import NoHostSync

    path = tmp_path / "her.yaml"
    path.write_text(yaml.safe_dump({**SPEC, **HER, "tracking": {"storage": str(tmp_path / "results")}}))
    pair = _trial(str(path), [0, 1])
    pair.train()  # the replay holds both seeds' transitions
    updates = pair.stack.updates
    noise, sampler, active = updates.step.noise.counters, updates.replay.sampler.counters, updates._active
    active.fill_(True)
    with NoHostSync():  # the call a trial's round makes, eager here: no host read, no host data in it
        updates._run()()
    recorder = Recorder()
    recorder.install(monkeypatch)
    monkeypatch.setattr(updates, "device", torch.device("cuda"))  # (the decision only: tensors stay put)
    updates._cached = None
    run = updates._run()
    monkeypatch.setattr(updates, "device", torch.device("cpu"))
    assert isinstance(run, CapturedCall)
    active.fill_(True)
    before = noise.clone()
    outs = [run() for _ in range(5)]
    assert run.captured and recorder.events.count("replay") == 2
    assert (noise > before).all()  # both seeds' streams advanced by the eager and capturing calls
    assert outs[3] is outs[4] and set(outs[3]) >= {"qf_loss", "finite", "total_loss"}
    assert updates.step.noise.counters is noise and updates.replay.sampler.counters is sampler
    assert updates._active is active and updates._run() is run  # the same call while storage stays
    pair.stop()


def test_without_batch_step_each_seeds_env_steps_itself_to_the_same_episodes(ray_session, tmp_path):
    """An env without `batch_step` (the Ant, the walker) steps each seed's env in the loop; on the maze
    that gives what one `batch_step` for all seeds gives, figure for figure."""
    path = tmp_path / "her.yaml"
    path.write_text(yaml.safe_dump({**SPEC, **HER, "tracking": {"storage": str(tmp_path / "results")}}))
    batched, looped = _trial(str(path), [0, 1]), _trial(str(path), [0, 1])
    assert batched.stack._move is not None
    looped.stack._move = None  # as for an env without batch_step
    moves = []
    move = batched.stack._move
    batched.stack._move = lambda ids, actions: moves.append(len(ids)) or move(ids, actions)
    one, other = batched.train(), looped.train()
    assert max(moves) == 2  # both seeds' agents moved in one call
    for seed in (0, 1):
        _assert_same(_figures(one, seed), _figures(other, seed), f"seed {seed}: batch_step vs its own step")
    assert one[keys.SEED_RESULTS]["0"][keys.ENV_STEPS] > 0
    batched.stop()
    looped.stop()
