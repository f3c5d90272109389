"""N seeds' rings in one storage: `FlatTransitionBuffer` and `HindsightReplayBuffer` with a ring per
seed. Each seed keeps exactly what its own one-seed buffer would keep, a sample gives every seed rows of
its own (HER's relabelled within that seed's episodes), the rows and goals its own one-seed buffer draws
(one sampler: each seed's Philox stream), and a seed's checkpoint is the one-seed format (either way
round, its stream's counter included)."""

import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac import (
    FlatTransitionBuffer,
    GoalLayout,
    HindsightReplayBuffer,
)
from copilot_ray.algorithms.gc_sac.replay_buffer import OBS, REWARDS, TERMINATEDS


def StackedTransitionBuffer(num_seeds, capacity, device, obs_dim, action_dim, seeds=None):  # noqa: N802
    """A flat buffer with a ring per seed (seeds 0 ... N - 1 unless given)."""
    seeds = range(num_seeds) if seeds is None else seeds
    return FlatTransitionBuffer(capacity, device, obs_dim, action_dim, seeds=seeds)


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
    alone = [FlatTransitionBuffer(10, device="cpu") for _ in range(3)]
    adds = {0: [4, 4], 1: [7, 6, 9], 2: [25]}  # no wrap, wraps twice, one add over the capacity
    for seed, sizes in adds.items():
        start = 0
        for n in sizes:
            assert (
                stack.add(seed=seed, transitions=_rows(seed, start, n))
                == alone[seed].add(_rows(seed, start, n))
                == n
            )
            start += n
    for seed in range(3):
        mine, want = stack.transitions(seed=seed), alone[seed].transitions()
        assert mine.keys() == want.keys()
        for key in want:
            np.testing.assert_array_equal(mine[key], want[key], err_msg=f"seed {seed} {key}")
        assert stack.get_state(seed=seed)["num_added"] == sum(adds[seed])
    assert stack.sizes.tolist() == [8, 10, 10] and len(stack) == 8


def test_a_sample_gives_every_seed_filled_rows_of_its_own():
    stack = StackedTransitionBuffer(3, capacity=50, device="cpu", obs_dim=2, action_dim=2)
    for seed, n in enumerate((3, 40, 12)):
        stack.add(seed=seed, transitions=_rows(seed, 0, n))
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
    stack.add(seed=0, transitions=_rows(0, 0, 11))  # wrapped
    flat = FlatTransitionBuffer(8)
    flat.set_state(stack.get_state(seed=0))
    np.testing.assert_array_equal(flat.transitions()["obs"], stack.transitions(seed=0)["obs"])
    # seed 0's rows restored as ring 1 of another stack (whose ring 1 is seed 0: its stream comes along)
    other = StackedTransitionBuffer(2, capacity=8, device="cpu", obs_dim=2, action_dim=2, seeds=(3, 0))
    other.set_state(seed=1, state=flat.get_state())
    np.testing.assert_array_equal(other.transitions(seed=1)["obs"], stack.transitions(seed=0)["obs"])
    assert other.sizes.tolist() == [0, 8]
    other.set_state(seed=0, state=FlatTransitionBuffer(8, seed=3).get_state())  # empty: the storage stays
    other.add(seed=0, transitions=_rows(0, 0, 2))
    assert other.sizes.tolist() == [2, 8] and other.transitions(seed=0)["obs"][1, 1] == 1.0


def test_a_stack_refuses_what_does_not_fit():
    stack = StackedTransitionBuffer(2, capacity=8, device="cpu", obs_dim=2, action_dim=2)
    before = stack.get_state(seed=1)
    with pytest.raises(
        ValueError, match=r"seed 1: a snapshot of capacity 16, .* does not fit the stack's \(capacity 8"
    ):
        stack.set_state(seed=1, state=FlatTransitionBuffer(16).get_state())
    assert stack.get_state(seed=1) == before
    with pytest.raises(ValueError, match="action size 3 != buffer action_dim 2"):
        stack.add(seed=0, transitions={**_rows(0, 0, 2), "actions": np.zeros((2, 3), np.float32)})
    with pytest.raises(ValueError, match="needs at least one seed"):
        StackedTransitionBuffer(0, capacity=8, device="cpu", obs_dim=2, action_dim=2)


# ------------------------------------------------------------------------ HER's buffer, stacked
LAYOUT = GoalLayout(obs_dim=2, goal_dim=2, with_delta=True)


def _reached_reward(next_achieved, goals, collisions):
    reached = torch.linalg.norm(next_achieved - goals, dim=1) <= 0.01
    return reached.double() - 0.5 * collisions.double(), reached


def _line(buffer, x0, steps, goal=(9.0, 9.0), seed=None):
    """An episode moving +1 in x per step from (x0, 0); achieved goal = observation; it collides at 2.
    Into ring `seed` of a buffer with a ring per seed (or a one-seed buffer's)."""
    pos = np.stack([x0 + np.arange(steps + 1), np.zeros(steps + 1)], axis=1).astype(np.float32)
    collisions = np.arange(steps) == 2
    ring = {} if seed is None else {"seed": seed}
    buffer.add_episode(
        pos, pos, np.array(goal, np.float32), np.ones((steps, 1)), np.zeros(steps), False, collisions, **ring
    )


def _her_stack(num_seeds=3, capacity=1000, seeds=None, **kwargs):
    """HER's device buffer with a ring per seed (seeds 0 ... N - 1 unless given)."""
    seeds = range(num_seeds) if seeds is None else seeds
    return HindsightReplayBuffer(capacity, LAYOUT, _reached_reward, seeds=seeds, **kwargs)


def test_each_seeds_her_buffer_keeps_what_its_own_buffer_keeps():
    stack = _her_stack(2, capacity=12)
    alone = HindsightReplayBuffer(12, LAYOUT, _reached_reward, seed=1)  # seed 1's: its sampler's too
    for x0, steps in ((0, 5), (100, 6), (200, 4)):  # the third wraps the ring
        _line(stack, x0, steps, seed=1)
        _line(alone, x0, steps)
    mine, want = stack.get_state(seed=1), alone.get_state()
    assert {k: v for k, v in mine.items() if k != "data"} == {k: v for k, v in want.items() if k != "data"}
    for key in want["data"]:
        np.testing.assert_array_equal(mine["data"][key], want["data"][key], err_msg=key)
    assert stack.sizes.tolist() == [0, 12] and len(stack) == 0


def test_a_stacked_her_sample_relabels_each_seed_within_its_own_episodes():
    stack = _her_stack(3)
    for seed in range(3):  # seed s moves in x from 1000 s: two episodes each
        _line(stack, 1000 * seed, 10, seed=seed)
        _line(stack, 1000 * seed + 100, 10, seed=seed)
    batch = stack.sample(2000)
    assert batch[OBS].shape == (3, 2000, 6) and batch[REWARDS].shape == (3, 2000)
    for seed in range(3):
        obs, goal = (t.numpy() for t in LAYOUT.split(batch[OBS][seed]))
        x = obs[:, 0]
        assert ((x >= 1000 * seed) & (x < 1000 * seed + 111)).all()  # its own transitions
        relabelled = goal[:, 1] != 9.0  # the real goal has y = 9, a relabelled one y = 0
        assert relabelled[:1600].all() and not relabelled[1600:].any()  # the first her_ratio = 4/5
        g = goal[relabelled, 0]
        assert ((x[relabelled] < 1000 * seed + 50) == (g < 1000 * seed + 50)).all()  # its own episode
        assert (g >= x[relabelled] + 1).all()  # "future": this step's next achieved goal or a later one
        np.testing.assert_allclose(batch[OBS][seed][:, 4:].numpy(), goal - obs)  # goal - achieved rebuilt
        # rewards recomputed for the new goals: 1 where the step reaches it, -0.5 for the collision at step 2
        reached = np.isclose(g, x[relabelled] + 1)
        collided = np.isin(x[relabelled] - 1000 * seed, (2, 102))
        want = reached.astype(float) - 0.5 * collided
        np.testing.assert_allclose(batch[REWARDS][seed].numpy()[relabelled], want)
        assert (batch[TERMINATEDS][seed].numpy()[relabelled] == reached).all()


def test_a_stacked_her_seeds_state_is_the_one_seed_format_and_bad_input_is_named():
    stack = _her_stack(2, capacity=50)
    _line(stack, 0, 8, seed=0)
    plain = HindsightReplayBuffer(50, LAYOUT, lambda *a: None)
    plain.set_state(stack.get_state(seed=0))
    other = _her_stack(2, capacity=50, seeds=(3, 0))  # ring 1 is seed 0: its stream comes along
    other.set_state(plain.get_state(), seed=1)
    np.testing.assert_array_equal(
        other.get_state(seed=1)["data"]["next_achieved"],
        stack.get_state(seed=0)["data"]["next_achieved"],
    )
    assert other.sizes.tolist() == [0, 8]
    with pytest.raises(ValueError, match="action size 3 != buffer action size 1"):
        pos = np.zeros((3, 2), np.float32)
        other.add_episode(
            pos, pos, np.zeros(2, np.float32), np.ones((2, 3)), np.zeros(2), False, np.zeros(2, bool), seed=0
        )
    wide = _her_stack(2, capacity=50)
    pos = np.zeros((3, 2), np.float32)
    wide.add_episode(
        pos, pos, np.zeros(2, np.float32), np.ones((2, 2)), np.zeros(2), False, np.zeros(2, bool), seed=1
    )
    with pytest.raises(ValueError, match="seed 0: a snapshot of action size 1 does not fit the stack's 2"):
        wide.set_state(plain.get_state(), seed=0)
    assert wide.get_state(seed=0)["action_dim"] == 2 and len(wide) == 0  # untouched
    with pytest.raises(ValueError, match="a checkpoint of capacity 50 into a buffer of 60"):
        _her_stack(1, capacity=60).set_state(plain.get_state(), seed=0)
    with pytest.raises(ValueError, match="goal_selection='best' is invalid"):
        _her_stack(1, goal_selection="best")
    with pytest.raises(ValueError, match="capacity must be > 0, got 0"):
        _her_stack(1, capacity=0)


def test_a_stacked_seeds_episode_goals_stay_in_its_episode_after_its_ring_wraps():
    """goal_selection "episode", each seed's 10 rows overwritten at the start of its second episode by
    its third (6, 6, then 5 steps; seed 1 one step longer each, so the seeds' rings differ): a goal is
    from the sampled row's own episode, per seed's own write pointer."""
    stack = _her_stack(2, capacity=10, goal_selection="episode")
    for seed in range(2):
        for x0, steps in ((0, 6), (100, 6), (200, 5)):
            _line(stack, 1000 * seed + x0, steps + seed, seed=seed)
    assert stack.pointers.tolist() == [7, 0]
    torch.manual_seed(0)
    batch = stack.sample(3000)
    for seed in range(2):
        obs, goal = (t.numpy() for t in LAYOUT.split(batch[OBS][seed]))
        relabelled = goal[:, 1] != 9.0
        episode = lambda x: np.floor_divide(x - 1000 * seed, 100)  # noqa: B023, E731
        assert (episode(goal[relabelled, 0]) == episode(obs[relabelled, 0])).all()


def test_a_stacked_seed_samples_the_rows_and_goals_its_one_seed_buffer_samples():
    seeds = (5, 7, 9)
    flat = StackedTransitionBuffer(3, capacity=30, device="cpu", obs_dim=2, action_dim=2, seeds=seeds)
    her = _her_stack(3, capacity=40, seeds=seeds)
    for i in range(len(seeds)):
        flat.add(seed=i, transitions=_rows(i, 0, 10 + 5 * i))
        _line(her, 100 * i, 8, seed=i)
        _line(her, 100 * i + 50, 6, seed=i)
    flat_alone = FlatTransitionBuffer(30, device="cpu", seed=7)
    flat_alone.add(_rows(1, 0, 15))
    her_alone = HindsightReplayBuffer(40, LAYOUT, _reached_reward, seed=7)
    _line(her_alone, 100, 8)
    _line(her_alone, 150, 6)
    active = torch.tensor([False, True, True])
    for _ in range(3):  # seed 5 sits out: seeds 7 and 9 draw on, 7's draws are its own buffer's
        for stack, alone in ((flat, flat_alone), (her, her_alone)):
            batch, own = stack.sample(20, active=active), alone.sample(20)
            for key, column in own.items():
                assert torch.equal(batch[key][1], column[0]), key
    assert flat.sampler.counters.tolist()[0] == 0 and her.sampler.counters.tolist()[0] == 0
    # A seed's buffer checkpoints its stream's counter; its one-seed buffer takes it, and draws on alike.
    restored = FlatTransitionBuffer(30, device="cpu", seed=7)
    restored.set_state(flat.get_state(seed=1))
    assert torch.equal(restored.sample(20)["obs"][0], flat.sample(20)["obs"][1])
    with pytest.raises(ValueError, match="does not fit these streams"):
        FlatTransitionBuffer(30, device="cpu", seed=8).set_state(flat.get_state(seed=1))


def test_sorbs_replayed_states_come_from_the_asked_seeds_ring():
    stack = _her_stack(2, capacity=40)
    _line(stack, 0, 8, seed=0)
    _line(stack, 500, 8, seed=1)
    observations, achieved = stack.sample_states(6, np.random.default_rng(0), seed=1)
    assert observations.shape == (6, 2) and (observations[:, 0] >= 500).all()
    np.testing.assert_array_equal(observations, achieved)  # this episode's achieved goal is its position
    assert (stack.sample_states(6, np.random.default_rng(0), seed=0)[0][:, 0] < 500).all()
