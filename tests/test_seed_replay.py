"""`seed_replay.StackedTransitionBuffer`: N seeds' rings in one storage. Each seed keeps exactly what
its own `DeviceTransitionBuffer` would keep, a sample gives every seed rows of its own, and a seed's
checkpoint is the one-seed format (either way round)."""

import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac import DeviceTransitionBuffer, FlatTransitionBuffer
from copilot_ray.algorithms.gc_sac.seed_replay import StackedTransitionBuffer


def _rows(seed, start, n):
    """n transitions whose obs name the seed and their index: obs = [seed, start + k]."""
    idx = np.arange(start, start + n, dtype=np.float32)
    obs = np.stack([np.full(n, seed, np.float32), idx], axis=1)
    return {
        "obs": obs,
        "new_obs": obs + 0.5,
        "actions": np.stack([idx, -idx], axis=1),
        "rewards": -idx,
        "terminateds": idx % 3 == 0,
    }


def test_each_seed_keeps_what_its_own_buffer_keeps_through_wraps():
    stack = StackedTransitionBuffer(3, capacity=10, device="cpu", obs_dim=2, action_dim=2)
    alone = [DeviceTransitionBuffer(10, device="cpu") for _ in range(3)]
    adds = {0: [4, 4], 1: [7, 6, 9], 2: [25]}  # no wrap, wraps twice, one add over the capacity
    for seed, sizes in adds.items():
        start = 0
        for n in sizes:
            assert stack.seeds[seed].add(_rows(seed, start, n)) == alone[seed].add(_rows(seed, start, n)) == n
            start += n
    for seed in range(3):
        mine, want = stack.seeds[seed].transitions(), alone[seed].transitions()
        assert mine.keys() == want.keys()
        for key in want:
            np.testing.assert_array_equal(mine[key], want[key], err_msg=f"seed {seed} {key}")
        assert stack.seeds[seed].num_added == sum(adds[seed])
    assert stack.sizes.tolist() == [8, 10, 10] and len(stack) == 8


def test_a_sample_gives_every_seed_filled_rows_of_its_own():
    stack = StackedTransitionBuffer(3, capacity=50, device="cpu", obs_dim=2, action_dim=2)
    for seed, n in enumerate((3, 40, 12)):
        stack.seeds[seed].add(_rows(seed, 0, n))
    torch.manual_seed(0)
    batch = stack.sample(500)
    assert batch["obs"].shape == (3, 500, 2) and batch["rewards"].shape == (3, 500)
    for seed, n in enumerate((3, 40, 12)):
        obs = batch["obs"][seed]
        assert bool((obs[:, 0] == seed).all())  # its own rows ...
        index = obs[:, 1]
        assert 0 <= float(index.min()) and float(index.max()) <= n - 1  # ... of the filled part only
        assert len(torch.unique(index)) == n  # 500 draws reach every filled row
        # the columns of a sampled transition stay aligned
        torch.testing.assert_close(batch["actions"][seed][:, 0], index)
        torch.testing.assert_close(batch["rewards"][seed], -index)
        torch.testing.assert_close(batch["new_obs"][seed], obs + 0.5)


def test_a_seeds_state_is_the_one_seed_format_both_ways():
    stack = StackedTransitionBuffer(2, capacity=8, device="cpu", obs_dim=2, action_dim=2)
    stack.seeds[0].add(_rows(0, 0, 11))  # wrapped
    flat = FlatTransitionBuffer(8)
    flat.set_state(stack.seeds[0].get_state())
    np.testing.assert_array_equal(flat.transitions()["obs"], stack.seeds[0].transitions()["obs"])
    other = StackedTransitionBuffer(2, capacity=8, device="cpu", obs_dim=2, action_dim=2)
    other.seeds[1].set_state(flat.get_state())  # seed 0's rows restored as seed 1 of another stack
    np.testing.assert_array_equal(other.seeds[1].transitions()["obs"], stack.seeds[0].transitions()["obs"])
    assert other.sizes.tolist() == [0, 8]
    other.seeds[0].set_state(FlatTransitionBuffer(8).get_state())  # an empty snapshot keeps the rows' views
    other.seeds[0].add(_rows(0, 0, 2))
    assert other.sizes.tolist() == [2, 8] and float(other.storage["obs"][0, 1, 1]) == 1.0


def test_a_stack_refuses_what_does_not_fit():
    stack = StackedTransitionBuffer(2, capacity=8, device="cpu", obs_dim=2, action_dim=2)
    before = stack.seeds[1].get_state()
    with pytest.raises(
        ValueError, match="seed 1: a snapshot of capacity 16 does not fit the stack's capacity 8"
    ):
        stack.seeds[1].set_state(FlatTransitionBuffer(16).get_state())
    assert stack.seeds[1].get_state() == before
    with pytest.raises(ValueError, match="action size 3 != buffer action_dim 2"):
        stack.seeds[0].add({**_rows(0, 0, 2), "actions": np.zeros((2, 3), np.float32)})
    with pytest.raises(ValueError, match="num_seeds must be >= 1, got 0"):
        StackedTransitionBuffer(0, capacity=8, device="cpu", obs_dim=2, action_dim=2)
