"""The three fixed task sets every goal env offers: `train`, `validation` and `test`.

An algorithm trains on `train` tasks only. Tuning, probes and the choice of defaults read success on
`validation` tasks; reports read `test` tasks. The three are drawn from separate seed streams of the
env's `task_seed` and checked pairwise disjoint, so that nothing chosen on validation tasks has seen a
test task. `uniform` is not a set: fresh tasks drawn at every reset.

The train and test streams are the ones the envs used before the validation set existed, so a test
task of an older run is the same task today.

`test_set` (an env config key) says which tasks the `test` set holds: `original` (the stream every run
used until 2026-11-28) or `fresh`, drawn from a stream of its own and checked disjoint from the three
others (the original test set included). Defaults were probed and chosen on runs that read the original
test tasks; the fresh ones were first read by the privilege-matched comparison
(`sweeps/privilege_matched.yaml`), so a comparison that reports on them has chosen nothing on them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

TASK_SETS = ("train", "validation", "test")
SPLIT_STREAMS = {"train": 0, "test": 1, "uniform": 2, "validation": 3, "fresh_test": 4}
# An env's `test_set` config value -> the seed stream its `test` set is drawn from.
TEST_SETS = {"original": "test", "fresh": "fresh_test"}


def split_rng(split: str, seed: int) -> np.random.Generator:
    """The random generator of one split's seed stream."""
    if split not in SPLIT_STREAMS:
        raise ValueError(f"unknown task split {split!r}; valid: {', '.join(SPLIT_STREAMS)}")
    return np.random.default_rng(np.random.SeedSequence([int(seed), SPLIT_STREAMS[split]]))


def check_task_set(split: str) -> None:
    if split not in TASK_SETS:
        raise ValueError(f"no fixed task set {split!r}; valid: {', '.join(TASK_SETS)}")


def check_test_set(value: object) -> str | None:
    """None when `value` names a test set (TEST_SETS), else what it must be."""
    return None if value in TEST_SETS else f"one of {', '.join(TEST_SETS)}"


def draw_task_sets(
    sample: Callable[[int, str], tuple[np.ndarray, np.ndarray]],
    sizes: Mapping[str, int],
    test_set: str = "original",
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every fixed set, `sample(n, stream)` each, checked pairwise disjoint (no (start, goal) pair twice).
    With `test_set="fresh"` the `test` set comes from its own stream, and is checked disjoint from the
    original test set too."""
    if check_test_set(test_set) is not None:
        raise ValueError(f"test_set={test_set!r} is invalid: must be {check_test_set(test_set)}")
    streams = {"train": "train", "validation": "validation", "test": TEST_SETS[test_set]}
    drawn = {stream: sample(int(sizes[name]), stream) for name, stream in streams.items()}
    if test_set != "original":
        drawn["test"] = sample(int(sizes["test"]), "test")
    rows = {name: {tuple(r) for r in np.concatenate(pair, axis=1).tolist()} for name, pair in drawn.items()}
    names = list(drawn)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            shared = rows[a] & rows[b]
            if shared:
                raise ValueError(f"the {a} and {b} task sets share {len(shared)} (start, goal) pair(s)")
    return {name: drawn[stream] for name, stream in streams.items()}
