"""`SeedStackTrial`'s bookkeeping, with a stand-in for each seed's algorithm (fast; no RLlib): what
Tune sees of a stack before its first evaluation, each seed's counters across a restore, and stopping.
The seeds' learning is `test_seed_stack_trial.py`'s."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml
from ray import tune

from copilot_ray import keys
from copilot_ray.algorithms.sac import trial as seed_stack_trial
from copilot_ray.algorithms.sac.trial import SeedStackTrial

SPEC = {
    "name": "stack",
    "env": {"id": "maze-point", "config": {"layout": "u-maze"}},
    "algorithm": "copilot",
    "seeds": [0, 1],
    "seeds_per_trial": 2,
    "searcher": {"type": "grid"},
    "stop": {"iterations": 5},
    "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
}
VALIDATION = keys.validation_key(keys.EVAL_SUCCESS)
STOPPED = []  # the seeds whose algorithm was stopped


class OneSeed(tune.Trainable):
    """A seed's algorithm as the stack sees it: env steps, and a validation figure that is NaN until
    its first evaluation at iteration 2 (as `SpecTrial` reports it); its iteration comes back with its
    checkpoint, as RLlib's state brings it back."""

    def setup(self, config):
        self.seed, self.steps = int(config[keys.SEED_PARAM]), 0

    def step(self):
        self.steps += 100 * (self.seed + 1)
        result = {}
        _set(result, keys.ENV_STEPS, float(self.steps))
        _set(result, VALIDATION, math.nan if self.iteration < 1 else 0.25 * (self.seed + 1))
        return result

    def save_checkpoint(self, checkpoint_dir):
        state = {"steps": self.steps, "iteration": self.iteration}
        Path(checkpoint_dir).mkdir(parents=True, exist_ok=True)  # (RLlib's save makes its folder)
        (Path(checkpoint_dir) / "state.json").write_text(json.dumps(state))

    def load_checkpoint(self, checkpoint_dir):
        state = json.loads((Path(checkpoint_dir) / "state.json").read_text())
        self.steps, self._iteration = state["steps"], state["iteration"]

    def cleanup(self):
        STOPPED.append(self.seed)
        if self.seed == 0 and getattr(self, "stop_fails", False):
            raise OSError("seed 0's env runner would not stop")


class LoopStandIn:
    """The stack's one loop, which trains nothing here: each stand-in seed does its work in `train()`."""

    def __init__(self, algos):
        self.algos = algos

    def run_iteration(self, indices):
        return {}

    def get_state(self):
        return {"seeds": len(self.algos)}

    def set_state(self, state):
        assert state == {"seeds": len(self.algos)}


def _set(result, dotted, value):
    *parents, leaf = dotted.split("/")
    for part in parents:
        result = result.setdefault(part, {})
    result[leaf] = value


def _get(result, dotted):
    for part in dotted.split("/"):
        result = result[part]
    return result


@pytest.fixture
def make_stack(tmp_path, monkeypatch):
    class Entry:
        @staticmethod
        def trial_class():
            return OneSeed

    monkeypatch.setattr(seed_stack_trial, "get_algorithm", lambda name: Entry())
    monkeypatch.setattr(seed_stack_trial, "SeedStack", LoopStandIn)
    path = tmp_path / "stack.yaml"
    path.write_text(yaml.safe_dump({**SPEC, "tracking": {"storage": str(tmp_path / "results")}}))
    STOPPED.clear()
    return lambda: SeedStackTrial(config={keys.SPEC_PATH_KEY: str(path), keys.SEEDS_KEY: [0, 1]})


def test_a_figure_no_seed_has_measured_yet_is_in_the_result_as_nan(make_stack):
    """Tune's strict metric check wants a scheduler's metric in every result: before the seeds' first
    evaluation the stack reports it as NaN, as a one-seed trial does, then the mean over the seeds."""
    stack = make_stack()
    first = stack.train()
    assert math.isnan(_get(first, VALIDATION))
    assert VALIDATION not in first[keys.SEED_RESULTS]["0"]  # each seed's MLflow rows: no NaN
    second = stack.train()
    assert _get(second, VALIDATION) == pytest.approx((0.25 + 0.5) / 2)
    assert _get(second, keys.ENV_STEPS) == 200  # the fewest env steps of a running seed
    stack.stop()


def test_each_seed_keeps_its_iteration_and_wall_time_across_a_restore(make_stack, tmp_path):
    stack = make_stack()
    for _ in range(2):
        before = stack.train()
    checkpoint = stack.save(str(tmp_path / "checkpoint"))
    stack.stop()
    restored = make_stack()
    restored.restore(checkpoint)
    after = restored.train()
    restored.stop()
    for seed in ("0", "1"):
        was, now = before[keys.SEED_RESULTS][seed], after[keys.SEED_RESULTS][seed]
        assert now[keys.TRAINING_ITERATION] == was[keys.TRAINING_ITERATION] + 1 == 3
        assert now[keys.TIME_TOTAL_S] >= was[keys.TIME_TOTAL_S] > 0  # not restarted at 0
        assert now[keys.ENV_STEPS] == was[keys.ENV_STEPS] * 3 / 2


def test_stopping_a_stack_stops_every_seed_even_when_one_stop_fails(make_stack):
    stack = make_stack()
    stack.train()
    stack.algos[0].stop_fails = True
    with pytest.raises(OSError, match="would not stop"):
        stack.cleanup()
    assert sorted(STOPPED) == [0, 1]
