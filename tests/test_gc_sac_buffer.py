"""FlatTransitionBuffer and its device twin DeviceTransitionBuffer: ring wrap-around, terminal flags,
episode conversion, sampling, state round trip (each restores the other's state)."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac import DeviceTransitionBuffer, FlatTransitionBuffer

OBS_SPACE = gym.spaces.Box(-10, 10, (3,), np.float32)
ACT_SPACE = gym.spaces.Box(-1, 1, (2,), np.float32)


def _rows(start, n):
    i = np.arange(start, start + n, dtype=np.float32)
    return {
        "obs": np.stack([i, i, i], 1),
        "new_obs": np.stack([i + 0.5] * 3, 1),
        "actions": np.stack([i, -i], 1),
        "rewards": i,
        "terminateds": (np.arange(start, start + n) % 3) == 0,
    }


def test_ring_wraps_and_keeps_newest():
    buf = FlatTransitionBuffer(capacity=5)
    buf.add(_rows(0, 3))
    assert len(buf) == 3 and buf.num_added == 3
    buf.add(_rows(3, 4))  # 7 rows into capacity 5: rows 2..6 survive
    assert len(buf) == 5 and buf.num_added == 7
    rows = buf.transitions()  # oldest first
    np.testing.assert_array_equal(rows["rewards"], [2, 3, 4, 5, 6])
    np.testing.assert_array_equal(rows["terminateds"], [False, True, False, False, True])
    np.testing.assert_array_equal(rows["new_obs"][:, 0], np.arange(2, 7) + 0.5)
    np.testing.assert_array_equal(buf.get_state()["data"]["rewards"], [5, 6, 2, 3, 4])  # storage order
    buf.add(_rows(10, 12))  # more than capacity at once: the newest 5
    np.testing.assert_array_equal(buf.transitions()["rewards"], np.arange(17, 22))


def test_sample_is_consistent_rows():
    buf = FlatTransitionBuffer(capacity=100)
    buf.add(_rows(0, 50))
    s = buf.sample(64, np.random.default_rng(0))
    assert s["obs"].shape == (64, 3) and s["actions"].shape == (64, 2) and s["rewards"].shape == (64,)
    assert s["obs"].dtype == np.float32 and s["terminateds"].dtype == bool
    np.testing.assert_array_equal(s["obs"][:, 0], s["rewards"])  # rows stay aligned
    np.testing.assert_array_equal(s["new_obs"][:, 0], s["rewards"] + 0.5)
    np.testing.assert_array_equal(s["terminateds"], (s["rewards"].astype(int) % 3) == 0)
    assert s["rewards"].max() < 50
    with pytest.raises(ValueError):
        FlatTransitionBuffer(4).sample(1, np.random.default_rng(0))


def _episode(obs_seq, terminated=False, truncated=False):
    from ray.rllib.env.single_agent_episode import SingleAgentEpisode

    ep = SingleAgentEpisode(observation_space=OBS_SPACE, action_space=ACT_SPACE)
    ep.add_env_reset(observation=obs_seq[0], infos={})
    for t in range(1, len(obs_seq)):
        last = t == len(obs_seq) - 1
        ep.add_env_step(
            observation=obs_seq[t],
            action=np.array([t, -t], np.float32),
            reward=float(t),
            infos={},
            terminated=terminated and last,
            truncated=truncated and last,
        )
    return ep


def test_add_episodes_terminated_truncated_and_chunks():
    o = [np.full(3, k, np.float32) for k in range(20)]
    term = _episode(o[0:4], terminated=True)  # 3 transitions, last terminated
    trunc = _episode(o[10:13], truncated=True).to_numpy()  # 2 transitions, truncated: keeps last next-obs
    # An ongoing episode sampled in two chunks: 3 steps, then (cut, continues from obs 7) 2 more + done.
    ongoing = _episode(o[4:8])
    chunk2 = ongoing.cut()
    for t, k in enumerate((8, 9), start=4):
        chunk2.add_env_step(
            observation=o[k],
            action=np.array([t, -t], np.float32),
            reward=float(t),
            infos={},
            terminated=k == 9,
        )
    buf = FlatTransitionBuffer(capacity=100)
    assert buf.add_episodes([term, trunc, ongoing, chunk2, _episode(o[15:16])]) == 3 + 2 + 3 + 2
    d = buf.transitions()
    np.testing.assert_array_equal(d["obs"][:, 0], [0, 1, 2, 10, 11, 4, 5, 6, 7, 8])
    np.testing.assert_array_equal(d["new_obs"][:, 0], [1, 2, 3, 11, 12, 5, 6, 7, 8, 9])
    np.testing.assert_array_equal(d["terminateds"], [0, 0, 1, 0, 0, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(d["truncateds"], [0, 0, 0, 0, 1, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(d["rewards"], [1, 2, 3, 1, 2, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(d["actions"][:, 0], d["rewards"])


def test_state_round_trip_after_wrap():
    buf = FlatTransitionBuffer(capacity=7)
    buf.add(_rows(0, 5))
    buf.add(_rows(5, 5))
    state = buf.get_state()
    restored = FlatTransitionBuffer.from_state(pickle.loads(pickle.dumps(state)))
    assert len(restored) == len(buf) == 7 and restored.num_added == 10
    for k, v in state["data"].items():
        np.testing.assert_array_equal(restored.get_state()["data"][k], v)
    # Same future behaviour: the next add overwrites the same (oldest) rows in both.
    buf.add(_rows(100, 2))
    restored.add(_rows(100, 2))
    np.testing.assert_array_equal(buf.transitions()["rewards"], restored.transitions()["rewards"])
    np.testing.assert_array_equal(buf.transitions()["rewards"], [5, 6, 7, 8, 9, 100, 101])
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    np.testing.assert_array_equal(buf.sample(9, rng_a)["obs"], restored.sample(9, rng_b)["obs"])
    copy = pickle.loads(pickle.dumps(buf))  # the buffer object itself pickles
    np.testing.assert_array_equal(
        copy.sample(5, np.random.default_rng(1))["rewards"],
        buf.sample(5, np.random.default_rng(1))["rewards"],
    )
    empty = FlatTransitionBuffer.from_state(FlatTransitionBuffer(3).get_state())
    assert len(empty) == 0


def test_the_device_buffer_keeps_the_same_rows_as_the_flat_one():
    flat, device = FlatTransitionBuffer(capacity=7), DeviceTransitionBuffer(capacity=7)
    o = [np.full(3, k, np.float32) for k in range(12)]
    for buf in (flat, device):
        buf.add(_rows(0, 5))
        buf.add(_rows(5, 5))  # wraps
        buf.add_episodes([_episode(o[0:4], terminated=True)])
    assert len(device) == len(flat) == 7 and device.num_added == flat.num_added == 13
    for key, rows in flat.transitions().items():
        np.testing.assert_array_equal(device.transitions()[key], rows, err_msg=key)
    device.add(_rows(100, 12))  # more than capacity at once: the newest 7
    np.testing.assert_array_equal(device.transitions()["rewards"], np.arange(105, 112))
    with pytest.raises(ValueError, match="action size 3 != buffer action_dim 2"):
        device.add({**_rows(0, 2), "actions": np.zeros((2, 3))})


def test_device_sampling_draws_aligned_rows_of_the_filled_part_only():
    buf = DeviceTransitionBuffer(capacity=1000)
    buf.add(_rows(0, 3))  # 3 of 1000 rows filled: a draw past them would read zeros
    batch = buf.sample(4000)
    assert batch["obs"].shape == (1, 4000, 3)  # one seed's batch
    s = {k: v[0] for k, v in batch.items()}
    assert s["obs"].shape == (4000, 3) and s["obs"].dtype == torch.float32
    assert s["terminateds"].dtype == torch.bool and set(s) == {
        "obs",
        "new_obs",
        "actions",
        "rewards",
        "terminateds",
    }
    assert sorted(set(s["rewards"].tolist())) == [0.0, 1.0, 2.0]  # every filled row, nothing else
    torch.testing.assert_close(s["obs"][:, 0], s["rewards"])  # rows stay aligned
    torch.testing.assert_close(s["new_obs"][:, 1], s["rewards"] + 0.5)
    assert torch.equal(s["terminateds"], (s["rewards"].long() % 3) == 0)
    counts = torch.bincount(s["rewards"].long()).tolist()
    assert min(counts) > 1200  # uniform: about 1333 each
    buf.add(_rows(3, 997))  # full: every row can come up, the last one too
    assert buf.sample(20_000)["rewards"].max().item() == 999.0


def test_device_and_flat_states_restore_into_each_other():
    flat = FlatTransitionBuffer(capacity=7)
    flat.add(_rows(0, 5))
    flat.add(_rows(5, 5))
    device = DeviceTransitionBuffer(capacity=1)
    device.set_state(pickle.loads(pickle.dumps(flat.get_state())))
    version = device.storage_version
    assert len(device) == 7 and device.num_added == 10 and device.capacity == 7
    for key, rows in flat.transitions().items():
        np.testing.assert_array_equal(device.transitions()[key], rows)
    flat.add(_rows(100, 2))
    device.add(_rows(100, 2))  # the same rows overwritten: the write pointer came along
    np.testing.assert_array_equal(device.transitions()["rewards"], flat.transitions()["rewards"])
    assert device.storage_version == version  # adding never moves the storage a graph reads
    back = FlatTransitionBuffer.from_state(device.get_state())
    for key, rows in flat.get_state()["data"].items():
        np.testing.assert_array_equal(back.get_state()["data"][key], rows)
    empty = DeviceTransitionBuffer(3)
    empty.set_state(FlatTransitionBuffer(3).get_state())
    assert len(empty) == 0
