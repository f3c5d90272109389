"""The three fixed task sets every goal env offers: `train`, `validation` and `test`.

An algorithm trains on `train` tasks only. Tuning, probes and the choice of defaults read success on
`validation` tasks; reports read `test` tasks. The three are drawn from separate seed streams of the
env's `task_seed` and checked pairwise disjoint, so that nothing chosen on validation tasks has seen a
test task. `uniform` is not a set: fresh tasks drawn at every reset.

The train and test streams are the ones the envs used before the validation set existed, so a test
task of an older run is the same task today.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

TASK_SETS = ("train", "validation", "test")
SPLIT_STREAMS = {"train": 0, "test": 1, "uniform": 2, "validation": 3}


def split_rng(split: str, seed: int) -> np.random.Generator:
    """The random generator of one split's seed stream."""
    if split not in SPLIT_STREAMS:
        raise ValueError(f"unknown task split {split!r}; valid: {', '.join(SPLIT_STREAMS)}")
    return np.random.default_rng(np.random.SeedSequence([int(seed), SPLIT_STREAMS[split]]))


def check_task_set(split: str) -> None:
    if split not in TASK_SETS:
        raise ValueError(f"no fixed task set {split!r}; valid: {', '.join(TASK_SETS)}")


def draw_task_sets(
    sample: Callable[[int, str], tuple[np.ndarray, np.ndarray]], sizes: Mapping[str, int]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every fixed set, `sample(n, split)` each, checked pairwise disjoint (no (start, goal) pair twice)."""
    sets = {name: sample(int(sizes[name]), name) for name in TASK_SETS}
    rows = {name: {tuple(r) for r in np.concatenate(pair, axis=1).tolist()} for name, pair in sets.items()}
    for i, a in enumerate(TASK_SETS):
        for b in TASK_SETS[i + 1 :]:
            shared = rows[a] & rows[b]
            if shared:
                raise ValueError(f"the {a} and {b} task sets share {len(shared)} (start, goal) pair(s)")
    return sets
