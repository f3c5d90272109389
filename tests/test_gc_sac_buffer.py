"""FlatTransitionBuffer (one seed's ring here; a stack's rings in test_seed_replay): ring wrap-around,
terminal flags, episode conversion, sampling on its device, state round trip."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac import FlatTransitionBuffer

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
    with pytest.raises(ValueError, match="action size 3 != buffer action_dim 2"):
        buf.add({**_rows(0, 2), "actions": np.zeros((2, 3))})
    with pytest.raises(ValueError, match="capacity must be > 0, got 0"):
        FlatTransitionBuffer(0)


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
    buf.sample(3)  # the sampler's counter moves, and comes along
    state = buf.get_state()
    restored = FlatTransitionBuffer(capacity=1)  # a one-seed buffer takes the snapshot's capacity
    restored.set_state(pickle.loads(pickle.dumps(state)))
    version = restored.storage_version
    assert len(restored) == len(buf) == 7 and restored.num_added == 10 and restored.capacity == 7
    for k, v in state["data"].items():
        np.testing.assert_array_equal(restored.get_state()["data"][k], v)
    # Same future behaviour: the next add overwrites the same (oldest) rows in both.
    buf.add(_rows(100, 2))
    restored.add(_rows(100, 2))
    assert restored.storage_version == version  # adding never moves the storage a graph reads
    np.testing.assert_array_equal(buf.transitions()["rewards"], restored.transitions()["rewards"])
    np.testing.assert_array_equal(buf.transitions()["rewards"], [5, 6, 7, 8, 9, 100, 101])
    torch.testing.assert_close(buf.sample(9)["obs"], restored.sample(9)["obs"])
    copy = pickle.loads(pickle.dumps(buf))  # the buffer object itself pickles
    torch.testing.assert_close(copy.sample(5)["rewards"], buf.sample(5)["rewards"])
    empty = FlatTransitionBuffer(3)
    empty.set_state(FlatTransitionBuffer(3).get_state())
    assert len(empty) == 0


def test_sampling_draws_aligned_rows_of_the_filled_part_only():
    buf = FlatTransitionBuffer(capacity=1000)
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
