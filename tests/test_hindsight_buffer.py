"""HER's replay buffer, numpy and on a device (every test runs on both): relabelled goals come from the
right place, rewards are recomputed, state round-trips (also from one kind into the other)."""

import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac import DeviceHindsightBuffer, GoalLayout, HindsightReplayBuffer
from copilot_ray.algorithms.gc_sac.replay_buffer import NEXT_OBS, OBS, REWARDS, TERMINATEDS

LAYOUT = GoalLayout(obs_dim=2, goal_dim=2, with_delta=True)
RADIUS = 0.01


def reward_fn(next_achieved, goals, collisions):
    reached = np.linalg.norm(next_achieved - goals, axis=1) <= RADIUS
    return np.where(reached, 1.0, 0.0) - 0.5 * collisions, reached


def torch_reward_fn(next_achieved, goals, collisions):
    reached = torch.linalg.norm(next_achieved - goals, dim=1) <= RADIUS
    return reached.double() - 0.5 * collisions.double(), reached


@pytest.fixture(params=["numpy", "device"])
def kind(request):
    return request.param


def draw(buffer, n, seed):
    """n transitions as numpy columns: the numpy buffer's own rng seeded `seed`, or the device buffer's
    own stream drawing on (its one seed's batch)."""
    if isinstance(buffer, DeviceHindsightBuffer):
        return {k: v[0].cpu().numpy() for k, v in buffer.sample(n).items()}
    return buffer.sample(n, np.random.default_rng(seed))


def line_episode(buffer, x0, steps, goal=(9.0, 9.0), collide_at=()):
    """An episode moving +1 in x per step from (x0, 0): achieved goal = observation."""
    pos = np.stack([x0 + np.arange(steps + 1), np.zeros(steps + 1)], axis=1).astype(np.float32)
    collisions = np.isin(np.arange(steps), collide_at)
    buffer.add_episode(
        pos, pos, np.array(goal, np.float32), np.ones((steps, 1)), np.zeros(steps), False, collisions
    )
    return pos


def make(kind, n_sampled_goal=4, capacity=1000, goal_selection="future"):
    if kind == "device":
        return DeviceHindsightBuffer(capacity, LAYOUT, torch_reward_fn, n_sampled_goal, goal_selection)
    return HindsightReplayBuffer(capacity, LAYOUT, reward_fn, n_sampled_goal, goal_selection)


def test_future_goals_come_from_the_same_episode_at_or_after_the_step(kind):
    buf = make(kind, n_sampled_goal=4)
    line_episode(buf, 0, 10)  # x = 0..10, episode A
    line_episode(buf, 100, 10)  # x = 100..110, episode B
    batch = draw(buf, 4000, 0)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    assert 0.75 < relabelled.mean() <= 0.8  # her_ratio 4/5 (the real goal has y = 9, relabelled ones y = 0)
    g, x = goal[relabelled, 0], obs[relabelled, 0]
    same_episode = (x < 50) == (g < 50)
    assert same_episode.all()
    # "future": the next achieved goal of this step or a later one
    assert (g >= x + 1).all()
    # the goal - achieved part is rebuilt for the new goal
    np.testing.assert_allclose(batch[OBS][:, 4:], goal - obs)


def test_relabelled_rewards_and_terminations_are_recomputed(kind):
    buf = make(kind, n_sampled_goal=4)
    line_episode(buf, 0, 6, collide_at=(2,))
    batch = draw(buf, 3000, 1)
    next_obs, goal = LAYOUT.split(batch[NEXT_OBS])
    reached = np.linalg.norm(next_obs - goal, axis=1) <= RADIUS
    assert reached.any() and (~reached).any()
    relabelled = goal[:, 1] != 9.0
    np.testing.assert_array_equal(batch[TERMINATEDS][relabelled], reached[relabelled])
    # reward 1 on reaching, -0.5 for the transition that collided (x 2 -> 3)
    expected = reached.astype(float) - 0.5 * (next_obs[:, 0] == 3.0)
    np.testing.assert_allclose(batch[REWARDS][relabelled], expected[relabelled])
    # transitions with their real goal keep their stored reward (0 here: the real goal is never reached)
    assert (batch[REWARDS][~relabelled] == 0).all()


def test_final_strategy_and_no_relabelling(kind):
    buf = make(kind, n_sampled_goal=1, goal_selection="final")
    line_episode(buf, 0, 5)
    _, goal = LAYOUT.split(draw(buf, 500, 2)[OBS])
    assert set(np.unique(goal[:, 0])) == {5.0, 9.0}  # the episode's last achieved goal, or the real one
    plain = make(kind, n_sampled_goal=0)
    line_episode(plain, 0, 5)
    _, goal = LAYOUT.split(draw(plain, 200, 2)[OBS])
    assert (goal[:, 0] == 9.0).all()


def test_future_goals_stay_valid_when_the_ring_wraps(kind):
    buf = make(kind, n_sampled_goal=4, capacity=25)
    for start in range(0, 1000, 100):  # ten 10-step episodes into 25 rows
        line_episode(buf, start, 10)
    assert len(buf) == 25 and buf.num_added == 100
    batch = draw(buf, 5000, 3)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    # a relabelled goal lies later on the same episode's line (episodes are 100 apart)
    assert (
        (goal[relabelled, 0] - obs[relabelled, 0] >= 1) & (goal[relabelled, 0] - obs[relabelled, 0] <= 10)
    ).all()


def test_state_round_trip_samples_the_same_batch(kind):
    buf = make(kind)
    for start in range(0, 500, 100):
        line_episode(buf, start, 7)
    copy = make(kind)
    copy.set_state(buf.get_state())
    a = draw(buf, 64, 4)
    b = draw(copy, 64, 4)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    line_episode(buf, 900, 3)
    line_episode(copy, 900, 3)
    np.testing.assert_array_equal(draw(buf, 32, 5)[OBS], draw(copy, 32, 5)[OBS])


def test_bad_arguments_are_named(kind):
    with pytest.raises(ValueError, match="goal_selection='later'"):
        make(kind, goal_selection="later")
    with pytest.raises(ValueError, match="n_sampled_goal must be >= 0"):
        make(kind, n_sampled_goal=-1)
    buf = make(kind)
    with pytest.raises(ValueError, match="needs 4 observations"):
        buf.add_episode(
            np.zeros((3, 2)),
            np.zeros((3, 2)),
            np.zeros(2),
            np.zeros((3, 1)),
            np.zeros(3),
            False,
            np.zeros(3, bool),
        )
    with pytest.raises(ValueError, match="empty"):
        draw(buf, 1, 0)


def test_a_goal_independent_dense_reward_is_kept_in_relabelled_rewards(kind):
    """The walker's own reward (info["dense_reward"]) does not depend on the goal: a relabelled
    transition gets the recomputed goal reward plus the stored dense one."""
    buf = make(kind, n_sampled_goal=4)
    steps = 6
    pos = np.stack([np.arange(steps + 1), np.zeros(steps + 1)], axis=1).astype(np.float32)
    dense = np.arange(steps, dtype=np.float32) / 10  # 0.0, 0.1, ... by the step's x
    buf.add_episode(
        pos,
        pos,
        np.array([9.0, 9.0], np.float32),
        np.ones((steps, 1)),
        dense,
        False,
        np.zeros(steps, bool),
        dense,
    )
    batch = draw(buf, 2000, 2)
    obs, goal = LAYOUT.split(batch[OBS])
    next_obs, _ = LAYOUT.split(batch[NEXT_OBS])
    relabelled = goal[:, 1] != 9.0
    reached = np.linalg.norm(next_obs - goal, axis=1) <= RADIUS
    np.testing.assert_allclose(batch[REWARDS], reached * relabelled + obs[:, 0] / 10, rtol=1e-6)


def test_episode_goals_come_from_anywhere_in_the_same_episode(kind):
    buf = make(kind, n_sampled_goal=4, goal_selection="episode")
    line_episode(buf, 0, 10)
    line_episode(buf, 100, 10)
    batch = draw(buf, 4000, 6)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    g, x = goal[relabelled, 0], obs[relabelled, 0]
    assert ((x < 50) == (g < 50)).all()
    start = np.where(x < 50, 0, 100)
    assert ((g >= start + 1) & (g <= start + 10)).all()  # some next achieved goal of the episode
    assert (g <= x).any() and (g > x + 1).any()  # earlier steps' goals too, unlike "future"


def test_either_kind_restores_the_others_state():
    host, device = make("numpy"), make("device")
    for start in range(0, 500, 100):
        line_episode(host, start, 7)
    device.set_state(host.get_state())
    for key, rows in host.get_state()["data"].items():
        np.testing.assert_array_equal(device.get_state()["data"][key], rows, err_msg=key)
    line_episode(host, 900, 3)
    line_episode(device, 900, 3)
    back = make("numpy")
    back.set_state(device.get_state())
    for key, rows in host.get_state()["data"].items():
        np.testing.assert_array_equal(back.get_state()["data"][key], rows, err_msg=key)
    device_states = device.sample_states(10, np.random.default_rng(0))
    host_states = host.sample_states(10, np.random.default_rng(0))
    for got, want in zip(device_states, host_states, strict=True):
        np.testing.assert_array_equal(got, want)


def test_episode_goals_stay_in_the_episode_when_the_ring_has_overwritten_its_start(kind):
    """Three episodes (6, 6 and 5 steps) into 10 rows: the third overwrites the second's first rows, so
    a goal drawn from anywhere in the second must come from its rows still stored, not the third's."""
    buf = make(kind, n_sampled_goal=4, capacity=10, goal_selection="episode")
    for start in (0, 100, 200):  # episodes 100 apart on the x axis
        line_episode(buf, start, {0: 6, 100: 6, 200: 5}[start])
    batch = draw(buf, 5000, 4)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    episode_of = lambda x: np.floor_divide(x, 100)  # noqa: E731
    assert relabelled.sum() > 1000
    assert (episode_of(goal[relabelled, 0]) == episode_of(obs[relabelled, 0])).all()
    # and the second episode's goals still reach back past its sampled steps (not "future" in disguise)
    second = relabelled & (episode_of(obs[:, 0]) == 1)
    assert (goal[second, 0] <= obs[second, 0]).any()
