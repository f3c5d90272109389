"""Every goal env's three fixed task sets: train, validation and test, disjoint and stable under a seed."""

import numpy as np
import pytest

from copilot_ray.envs import make
from copilot_ray.envs.task_sets import TASK_SETS, draw_task_sets


def _pairs(starts, goals) -> set[tuple]:
    return {tuple(r) for r in np.concatenate([starts, goals], axis=1).tolist()}


def test_maze_sets_are_disjoint_sized_from_the_config_and_stable_under_the_seed():
    env = make("maze-point", layout="u-maze", num_train_tasks=40, num_validation_tasks=15, num_test_tasks=10)
    sets = {name: env.unwrapped.tasks(name) for name in TASK_SETS}
    assert [len(sets[n][0]) for n in TASK_SETS] == [40, 15, 10]
    pairs = {name: _pairs(*sets[name]) for name in TASK_SETS}
    assert not pairs["train"] & pairs["validation"]
    assert not pairs["train"] & pairs["test"]
    assert not pairs["validation"] & pairs["test"]
    again = make(
        "maze-point", layout="u-maze", num_train_tasks=40, num_validation_tasks=15, num_test_tasks=10
    )
    for name in TASK_SETS:
        for a, b in zip(sets[name], again.unwrapped.tasks(name), strict=True):
            np.testing.assert_array_equal(a, b)
    other = make("maze-point", layout="u-maze", num_validation_tasks=15, task_seed=1)
    assert not np.array_equal(other.unwrapped.tasks("validation")[0], sets["validation"][0])


def test_the_test_set_did_not_move_when_the_validation_set_came():
    """The test stream is the one the envs used before: adding validation tasks changed no test task
    (so earlier results were on the same tasks). Its first task, drawn at commit 6daa388."""
    starts, goals = make("maze-point").unwrapped.tasks("test")
    assert len(starts) == 100
    np.testing.assert_allclose(starts[0], [0.8897388, 0.5571380], atol=1e-6)
    np.testing.assert_allclose(goals[0], [0.2734274, 0.7075338], atol=1e-6)


def test_an_unknown_set_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"no fixed task set 'valid'; valid: train, validation, test"):
        make("maze-point").unwrapped.tasks("valid")


def test_overlapping_sets_are_refused():
    def sample(n, split):  # every split draws the same pairs
        return np.zeros((n, 2), np.float32), np.ones((n, 2), np.float32)

    with pytest.raises(ValueError, match=r"the train and validation task sets share 1"):
        draw_task_sets(sample, {"train": 3, "validation": 2, "test": 2})


def test_ant_maze_and_walker_have_validation_sets_too():
    ant = make("ant-maze").unwrapped
    pairs = {name: _pairs(*ant.tasks(name)) for name in TASK_SETS}
    assert [len(p) for p in pairs.values()] == [50, 10, 10]
    assert not pairs["validation"] & (pairs["train"] | pairs["test"])
    ant.close()
    walker = make("walker-stumps", num_eval_distributions=3, tracks_per_distribution=2).unwrapped
    seeds = {name: {t.seed for t in walker.tracks(name)} for name in TASK_SETS}
    assert [len(seeds[n]) for n in TASK_SETS] == [3 * 20, 3 * 2, 3 * 2]
    assert not seeds["validation"] & (seeds["train"] | seeds["test"])
    walker.close()


def test_a_fresh_test_set_is_disjoint_from_the_other_three_and_the_original_test_set():
    """`test_set: fresh` draws the test tasks from a stream of their own: none is a train, validation or
    original test task, the train and validation sets stay the same, and the fresh set is stable."""
    fresh = make("maze-point", layout="four-rooms", test_set="fresh").unwrapped
    original = make("maze-point", layout="four-rooms").unwrapped
    for name in ("train", "validation"):
        for a, b in zip(fresh.tasks(name), original.tasks(name), strict=True):
            np.testing.assert_array_equal(a, b)
    new = _pairs(*fresh.tasks("test"))
    assert len(new) == 100
    for name in TASK_SETS:
        assert not new & _pairs(*original.tasks(name)), name
    again = make("maze-point", layout="four-rooms", test_set="fresh").unwrapped
    np.testing.assert_array_equal(again.tasks("test")[0], fresh.tasks("test")[0])


def test_a_fresh_test_set_that_meets_the_original_one_is_refused():
    def sample(n, stream):  # the fresh stream repeats the original test tasks
        base = 0.0 if stream in ("test", "fresh_test") else {"train": 1.0, "validation": 2.0}[stream]
        return np.full((n, 2), base, np.float32), np.full((n, 2), base + 0.5, np.float32)

    with pytest.raises(ValueError, match=r"the fresh_test and test task sets share 1"):
        draw_task_sets(sample, {"train": 2, "validation": 2, "test": 2}, test_set="fresh")


@pytest.mark.parametrize("env_id", ["maze-point", "ant-maze"])
def test_an_unknown_test_set_is_refused_naming_the_key_and_the_value(env_id):
    with pytest.raises(ValueError, match=r"test_set'\] = 'newest': must be one of original, fresh"):
        make(env_id, test_set="newest")
