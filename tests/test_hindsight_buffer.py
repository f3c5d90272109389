"""HER's replay buffer (one seed's ring here; a stack's rings in test_seed_replay): relabelled goals come
from the right place, rewards are recomputed, state round-trips."""

import numpy as np
import pytest
import torch

from copilot_ray.algorithms.gc_sac import GoalLayout, HindsightReplayBuffer
from copilot_ray.algorithms.gc_sac.replay_buffer import NEXT_OBS, OBS, REWARDS, TERMINATEDS

LAYOUT = GoalLayout(obs_dim=2, goal_dim=2, with_delta=True)
RADIUS = 0.01


def reward_fn(next_achieved, goals, collisions):
    reached = torch.linalg.norm(next_achieved - goals, dim=1) <= RADIUS
    return reached.double() - 0.5 * collisions.double(), reached


def draw(buffer, n):
    """n transitions of the buffer's one seed as numpy columns (its stream drawing on)."""
    return {k: v[0].cpu().numpy() for k, v in buffer.sample(n).items()}


def line_episode(buffer, x0, steps, goal=(9.0, 9.0), collide_at=()):
    """An episode moving +1 in x per step from (x0, 0): achieved goal = observation."""
    pos = np.stack([x0 + np.arange(steps + 1), np.zeros(steps + 1)], axis=1).astype(np.float32)
    collisions = np.isin(np.arange(steps), collide_at)
    buffer.add_episode(
        pos, pos, np.array(goal, np.float32), np.ones((steps, 1)), np.zeros(steps), False, collisions
    )
    return pos


def make(n_sampled_goal=4, capacity=1000, goal_selection="future"):
    return HindsightReplayBuffer(capacity, LAYOUT, reward_fn, n_sampled_goal, goal_selection)


def test_future_goals_come_from_the_same_episode_at_or_after_the_step():
    buf = make(n_sampled_goal=4)
    line_episode(buf, 0, 10)  # x = 0..10, episode A
    line_episode(buf, 100, 10)  # x = 100..110, episode B
    batch = draw(buf, 4000)
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


def test_relabelled_rewards_and_terminations_are_recomputed():
    buf = make(n_sampled_goal=4)
    line_episode(buf, 0, 6, collide_at=(2,))
    batch = draw(buf, 3000)
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


def test_final_strategy_and_no_relabelling():
    buf = make(n_sampled_goal=1, goal_selection="final")
    line_episode(buf, 0, 5)
    _, goal = LAYOUT.split(draw(buf, 500)[OBS])
    assert set(np.unique(goal[:, 0])) == {5.0, 9.0}  # the episode's last achieved goal, or the real one
    plain = make(n_sampled_goal=0)
    line_episode(plain, 0, 5)
    _, goal = LAYOUT.split(draw(plain, 200)[OBS])
    assert (goal[:, 0] == 9.0).all()


def test_future_goals_stay_valid_when_the_ring_wraps():
    buf = make(n_sampled_goal=4, capacity=25)
    for start in range(0, 1000, 100):  # ten 10-step episodes into 25 rows
        line_episode(buf, start, 10)
    assert len(buf) == 25 and buf.num_added == 100
    batch = draw(buf, 5000)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    # a relabelled goal lies later on the same episode's line (episodes are 100 apart)
    assert (
        (goal[relabelled, 0] - obs[relabelled, 0] >= 1) & (goal[relabelled, 0] - obs[relabelled, 0] <= 10)
    ).all()


def test_state_round_trip_samples_the_same_batch():
    buf = make()
    for start in range(0, 500, 100):
        line_episode(buf, start, 7)
    copy = make()
    copy.set_state(buf.get_state())
    a = draw(buf, 64)
    b = draw(copy, 64)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    line_episode(buf, 900, 3)
    line_episode(copy, 900, 3)
    np.testing.assert_array_equal(draw(buf, 32)[OBS], draw(copy, 32)[OBS])


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="goal_selection='later'"):
        make(goal_selection="later")
    with pytest.raises(ValueError, match="n_sampled_goal must be >= 0"):
        make(n_sampled_goal=-1)
    buf = make()
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
        draw(buf, 1)
    line_episode(buf, 0, 3)
    with pytest.raises(ValueError, match="action size 2 != buffer action size 1"):
        buf.add_episode(
            np.zeros((3, 2)),
            np.zeros((3, 2)),
            np.zeros(2),
            np.zeros((2, 2)),
            np.zeros(2),
            False,
            np.zeros(2, bool),
        )


def test_a_goal_independent_dense_reward_is_kept_in_relabelled_rewards():
    """The walker's own reward (info["dense_reward"]) does not depend on the goal: a relabelled
    transition gets the recomputed goal reward plus the stored dense one."""
    buf = make(n_sampled_goal=4)
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
    batch = draw(buf, 2000)
    obs, goal = LAYOUT.split(batch[OBS])
    next_obs, _ = LAYOUT.split(batch[NEXT_OBS])
    relabelled = goal[:, 1] != 9.0
    reached = np.linalg.norm(next_obs - goal, axis=1) <= RADIUS
    np.testing.assert_allclose(batch[REWARDS], reached * relabelled + obs[:, 0] / 10, rtol=1e-6)


def test_episode_goals_come_from_anywhere_in_the_same_episode():
    buf = make(n_sampled_goal=4, goal_selection="episode")
    line_episode(buf, 0, 10)
    line_episode(buf, 100, 10)
    batch = draw(buf, 4000)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    g, x = goal[relabelled, 0], obs[relabelled, 0]
    assert ((x < 50) == (g < 50)).all()
    start = np.where(x < 50, 0, 100)
    assert ((g >= start + 1) & (g <= start + 10)).all()  # some next achieved goal of the episode
    assert (g <= x).any() and (g > x + 1).any()  # earlier steps' goals too, unlike "future"


def test_sorbs_replayed_states_are_distinct_stored_rows():
    buf = make()
    for start in range(0, 500, 100):
        line_episode(buf, start, 7)
    observations, achieved = buf.sample_states(10, np.random.default_rng(0))
    assert observations.shape == (10, 2) and len(set(observations[:, 0].tolist())) == 10
    stored = {(x, y) for x, y in buf.get_state()["data"]["observation"].tolist()}
    assert {(x, y) for x, y in observations.tolist()} <= stored
    np.testing.assert_array_equal(achieved, observations)  # achieved goal = observation on the line
    assert buf.sample_states(100, np.random.default_rng(0))[0].shape == (35, 2)  # at most what is stored


def test_episode_goals_stay_in_the_episode_when_the_ring_has_overwritten_its_start():
    """Three episodes (6, 6 and 5 steps) into 10 rows: the third overwrites the second's first rows, so
    a goal drawn from anywhere in the second must come from its rows still stored, not the third's."""
    buf = make(n_sampled_goal=4, capacity=10, goal_selection="episode")
    for start in (0, 100, 200):  # episodes 100 apart on the x axis
        line_episode(buf, start, {0: 6, 100: 6, 200: 5}[start])
    batch = draw(buf, 5000)
    obs, goal = LAYOUT.split(batch[OBS])
    relabelled = goal[:, 1] != 9.0
    episode_of = lambda x: np.floor_divide(x, 100)  # noqa: E731
    assert relabelled.sum() > 1000
    assert (episode_of(goal[relabelled, 0]) == episode_of(obs[relabelled, 0])).all()
    # and the second episode's goals still reach back past its sampled steps (not "future" in disguise)
    second = relabelled & (episode_of(obs[:, 0]) == 1)
    assert (goal[second, 0] <= obs[second, 0]).any()
