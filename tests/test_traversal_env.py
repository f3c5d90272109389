"""The traversal env turns a sub-goal tree into RLlib episodes, one per sub-task (Algorithm 2)."""

import numpy as np
import pytest

from copilot_ray.algorithms.copilot.settings import PRESETS
from copilot_ray.algorithms.sac.traversal_env import TraversalEnv, TraversalRules, traversal_queue

# These tests read the paper literally unless a test names a rule: (s, g) observations, R / 2^k
# rewards, the next sub-task continues where the agent stopped. (The paper_literal preset keeps the
# baselines' agent input, goal - position included; the paper's own is (s, g).)
PAPER = {
    **{k: v for k, v in PRESETS["paper_literal"].items() if k in TraversalRules.__dataclass_fields__},
    "agent_input": "state_goal",
}
S0 = np.array([0.1, 0.1], np.float32)
G = np.array([0.9, 0.1], np.float32)


def straight_tree(depth: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, 2**depth + 1)[:, None]
    return (S0 + t * (G - S0)).astype(np.float32)


def make_env(tau_max=50, speed=0.01):
    return TraversalEnv(
        {
            "goal_env": "maze-point",
            "goal_env_config": {"layout": "empty", "speed": speed},
            **PAPER,
            "tau_max": tau_max,
        }
    )


def test_queue_order_is_bottom_up_layer_by_layer():
    depth = 2
    queue = traversal_queue(straight_tree(depth)[None], depth, np.array([7]))
    assert [(s.layer, s.index) for s in queue] == [(2, 1), (2, 2), (2, 3), (2, 4), (1, 1), (1, 2), (0, 1)]
    assert all(s.task_id == 7 for s in queue)
    # The first sub-task of each layer starts from s0; the others continue where the agent is.
    assert [s.start is not None for s in queue] == [True, False, False, False, True, False, True]
    np.testing.assert_allclose(queue[-1].goal, G)
    np.testing.assert_allclose(queue[0].goal, straight_tree(depth)[1])


def drive_to_goal(env, obs):
    """A scripted agent heading straight for its sub-goal (obs = [position, sub-goal])."""
    pos, goal = obs[:2], obs[2:]
    d = goal - pos
    return np.clip(d / max(np.linalg.norm(d), 1e-9), -1, 1).astype(np.float32)


def test_rewards_are_scaled_per_layer_and_traversal_records_subtasks():
    depth = 2
    env = make_env(tau_max=100)  # layer 0 needs ~78 steps at speed 0.01
    n = env.load_plan(straight_tree(depth)[None], depth, np.array([0]))
    assert n == 7
    finals = []
    returns = []
    while env.remaining():
        obs, _ = env.reset()
        total, done = 0.0, False
        while not done:
            obs, r, term, trunc, info = env.step(drive_to_goal(env, obs))
            total += r
            done = term or trunc
        finals.append(info)
        returns.append(total)
    layers = [i["subtask_layer"] for i in finals]
    assert layers == [2, 2, 2, 2, 1, 1, 0]
    assert all(i["subtask_reached"] for i in finals)
    # R / 2^k for a reached sub-task of layer k (R = 1 by default).
    np.testing.assert_allclose(returns, [0.25] * 4 + [0.5] * 2 + [1.0])
    # Each layer's first sub-task starts at s0.
    np.testing.assert_allclose(finals[0]["subtask_start"], S0, atol=1e-6)
    np.testing.assert_allclose(finals[4]["subtask_start"], S0, atol=1e-6)
    # A sub-task's steps are what it took: 0.2 of distance at speed 0.01 -> about 18 steps.
    assert 15 <= finals[0]["subtask_steps"] <= 20


def test_failed_subtask_truncates_at_tau_max_and_next_continues_in_place():
    depth = 1
    env = make_env(tau_max=5)
    env.load_plan(straight_tree(depth)[None], depth, np.array([0]))
    obs, _ = env.reset()
    steps = 0
    while True:
        obs, r, term, trunc, info = env.step(drive_to_goal(env, obs))
        steps += 1
        if term or trunc:
            break
    assert trunc and not term and steps == 5 and r == 0.0
    assert info["subtask_reached"] is False
    end = info["subtask_end"]
    obs, _ = env.reset()  # second sub-task of layer 1: starts where the first one stopped
    np.testing.assert_allclose(obs[:2], end, atol=1e-6)
    obs, _ = env.reset()  # layer 0 starts from s0 again
    np.testing.assert_allclose(obs[:2], S0, atol=1e-6)
    np.testing.assert_allclose(obs[2:], G, atol=1e-6)


def test_a_training_episode_length_truncates_training_episodes_but_not_the_evaluation_budget():
    """train_episode_steps (the agent-only baselines' knob): a training episode is truncated there,
    while the step limit evaluation reads (step_limit_of) stays tau_max."""
    env = TraversalEnv(
        {
            "goal_env": "maze-point",
            "goal_env_config": {"layout": "empty", "speed": 0.01},
            **PAPER,
            "tau_max": 50,
            "train_episode_steps": 7,
        }
    )
    env.load_plan(straight_tree(0)[None], 0, np.array([0]))
    obs, _ = env.reset()
    steps, trunc = 0, False
    while not trunc:
        obs, _, term, trunc, _ = env.step(drive_to_goal(env, obs))
        steps += 1
        assert not term
    assert steps == 7
    assert env.rules.step_limit_of(0, 0) == 50 and env.rules.training_step_limit_of(0, 0) == 7
    assert make_env(tau_max=50).rules.training_step_limit_of(0, 0) == 50  # null: tau_max


def test_reset_without_plan_gives_idle_episode():
    env = make_env(tau_max=3)
    env.reset()
    for _ in range(3):
        _, _, term, trunc, info = env.step(np.zeros(2, np.float32))
    assert trunc and info["subtask_idle"] is True


@pytest.mark.parametrize("depth", [1, 3])
def test_observation_space_contains_observations(depth):
    env = make_env()
    env.load_plan(straight_tree(depth)[None], depth, np.array([0]))
    obs, _ = env.reset()
    assert env.observation_space.contains(obs)


def make_ruled_env(**rules):
    config = {
        "goal_env": "maze-point",
        "goal_env_config": {"layout": "empty", "speed": 0.01},
        **PAPER,
        "tau_max": 5,
    }
    return TraversalEnv({**config, **rules})


def run_subtask(env, policy=drive_to_goal):
    obs, _ = env.reset()
    total, steps = 0.0, 0
    while True:
        obs, r, term, trunc, info = env.step(policy(env, obs))
        total += r
        steps += 1
        if term or trunc:
            return obs, total, steps, term, info


def finish_subtask(env, policy):
    """Steps the sub-task `env.reset()` already started until it ends; its last info."""
    while True:
        obs, _, term, trunc, info = env.step(policy(env, None))
        if term or trunc:
            return info


def stand_still(env, obs):
    return np.zeros(2, np.float32)


def test_scaled_step_limit_gives_layer_k_tau_max_times_2_to_the_K_minus_k():
    depth = 2
    env = make_ruled_env(step_limit="scaled")
    env.load_plan(straight_tree(depth)[None], depth, np.array([0]))
    steps = [run_subtask(env, stand_still)[2] for _ in range(7)]
    # layers 2, 2, 2, 2, 1, 1, 0 -> 5, 5, 5, 5, 10, 10, 20 steps before truncation
    assert steps == [5] * 4 + [10] * 2 + [20]
    fixed = make_ruled_env(step_limit="fixed")
    fixed.load_plan(straight_tree(depth)[None], depth, np.array([0]))
    assert [run_subtask(fixed, stand_still)[2] for _ in range(7)] == [5] * 7


def test_after_failure_restart_starts_the_next_subtask_at_the_missed_subgoal():
    depth = 1
    tree = straight_tree(depth)
    env = make_ruled_env(after_failure="restart")
    env.load_plan(tree[None], depth, np.array([0]))
    *_, info = run_subtask(env, stand_still)  # fails: stays at s0
    assert info["subtask_reached"] is False
    # the first sub-task of a layer starts at the task's start: no privilege used
    assert info["subtask_reset_to_state"] is False and info["subtask_map_queries"] == 0
    obs, _ = env.reset()  # next sub-task of the layer starts at the sub-goal it missed
    np.testing.assert_allclose(obs[:2], tree[1], atol=1e-6)
    np.testing.assert_allclose(obs[2:], tree[2], atol=1e-6)
    # ... after asking the map: a reset to a state that is no task's start, and a map query, counted
    info = finish_subtask(env, stand_still)
    assert info["subtask_reset_to_state"] is True and info["subtask_map_queries"] == 1


def test_continue_and_abort_layer_use_no_privilege():
    depth = 2
    for rule in ("continue", "abort_layer"):
        env = make_ruled_env(after_failure=rule)
        env.load_plan(np.stack([straight_tree(depth)] * 2), depth, np.array([0, 1]))
        while env.remaining():
            *_, info = run_subtask(env, stand_still)  # every sub-task fails
            assert info["subtask_reset_to_state"] is False and info["subtask_map_queries"] == 0, rule


def test_after_failure_restart_falls_back_to_the_agent_position_when_the_subgoal_is_in_a_wall():
    depth = 1
    tree = straight_tree(depth).copy()
    env = TraversalEnv(
        {
            "goal_env": "maze-point",
            "goal_env_config": {"layout": "u-maze", "speed": 0.01},
            **PAPER,
            "tau_max": 3,
            "after_failure": "restart",
        }
    )
    inner = env.inner
    starts, goals = inner.tasks("train")
    wall = np.array([0.5, 0.5], np.float32)
    assert not inner.is_free(wall)
    tree = np.stack([starts[0], wall, goals[0]])
    env.load_plan(tree[None], depth, np.array([0]))
    *_, info = run_subtask(env, stand_still)
    obs, _ = env.reset()
    np.testing.assert_allclose(obs[:2], info["subtask_end"], atol=1e-6)
    info = finish_subtask(env, stand_still)  # the map was asked, the answer was no: no reset
    assert info["subtask_map_queries"] == 1 and info["subtask_reset_to_state"] is False


def test_after_failure_abort_layer_drops_the_rest_of_the_layer():
    depth = 2
    env = make_ruled_env(after_failure="abort_layer")
    n = env.load_plan(np.stack([straight_tree(depth)] * 2), depth, np.array([0, 1]))
    assert n == 14
    *_, info = run_subtask(env, stand_still)  # task 0, layer 2, first sub-goal: fails
    assert (info["subtask_layer"], info["subtask_index"]) == (2, 1)
    # The three remaining sub-tasks of task 0's layer 2 are gone; layer 1 of task 0 is next.
    assert env.remaining() == 14 - 4
    *_, info = run_subtask(env, stand_still)
    assert (info["subtask_task"], info["subtask_layer"], info["subtask_index"]) == (0, 1, 1)


@pytest.mark.parametrize(
    ("mode", "scale", "expected"),
    [("halving", 1.0, 0.25), ("uniform", 1.0, 1.0), ("uniform", 3.0, 3.0), ("halving", 2.0, 0.5)],
)
def test_subtask_reward_modes(mode, scale, expected):
    depth = 2
    env = make_ruled_env(subtask_reward=mode, reward_scale=scale, tau_max=100)
    env.load_plan(straight_tree(depth)[None], depth, np.array([0]))
    _, total, _, term, _ = run_subtask(env)  # a layer-2 sub-task, reached
    assert term and total == pytest.approx(expected)


def into_the_wall(env, obs):
    return np.array([0.0, -1.0], np.float32)  # straight down into the border


@pytest.mark.parametrize(
    ("mode", "steps", "total"), [("none", 5, 0.0), ("penalty", 5, -0.5), ("terminate", 1, -0.1)]
)
def test_agent_collision_modes(mode, steps, total):
    depth = 1
    tree = straight_tree(depth).copy()
    tree[:, 1] = 0.005  # the path runs along the bottom border, 0.005 above it
    env = make_ruled_env(agent_collision=mode, agent_collision_penalty=0.1)
    env.load_plan(tree[None], depth, np.array([0]))
    _, got_total, got_steps, term, info = run_subtask(env, into_the_wall)
    assert got_steps == steps and got_total == pytest.approx(total)
    assert term == (mode == "terminate") and info["subtask_collided"] is True


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("step_limit", "linear"),
        ("after_failure", "retry"),
        ("subtask_reward", "dense"),
        ("agent_collision", "explode"),
        ("reward_scale", 0.0),
        ("agent_collision_penalty", -1.0),
        ("tau_max", 0),
    ],
)
def test_bad_traversal_rules_name_key_and_value(key, value):
    with pytest.raises(ValueError, match=rf"{key}={value!r}"):
        make_ruled_env(**{key: value})


def test_state_goal_delta_input_appends_subgoal_minus_position():
    depth = 1
    tree = straight_tree(depth)
    env = make_ruled_env(agent_input="state_goal_delta")
    assert env.observation_space.shape == (6,)
    env.load_plan(tree[None], depth, np.array([0]))
    obs, _ = env.reset()
    np.testing.assert_allclose(obs[4:], obs[2:4] - obs[:2], atol=1e-6)
    obs, *_ = env.step(np.array([1.0, 0.0], np.float32))
    np.testing.assert_allclose(obs[:2], tree[0] + [0.01, 0.0], atol=1e-6)
    np.testing.assert_allclose(obs[4:], tree[1] - obs[:2], atol=1e-6)
    assert env.observation_space.contains(obs)
    plain = make_ruled_env()
    assert plain.observation_space.shape == (4,)


def test_a_dense_env_reward_is_added_unscaled_to_the_sub_task_reward():
    """R / 2^k scales the goal reward only; the env's goal-independent reward (the walker's own) is
    added as it is, and the traversal env passes it on in its info."""
    rules = TraversalRules(subtask_reward="halving", reward_scale=200.0)
    reward, terminated = rules.reward(
        np.array([1.0, 0.0]), np.array([True, False]), np.zeros(2), 3, np.array([0.5, -2.0])
    )
    np.testing.assert_allclose(reward, [200.0 / 8 + 0.5, -2.0])
    np.testing.assert_array_equal(terminated, [True, False])
    env = TraversalEnv(
        {"goal_env": "walker-stumps", "goal_env_config": {"walker_reward_weight": 2.0}, "tau_max": 5}
    )
    tree = np.array([[[4.67], [80.0]]], np.float32)
    env.load_plan(tree, depth=0, task_ids=np.array([0]))
    env.reset()
    _, reward, _, _, info = env.step(np.zeros(4))
    assert info["dense_reward"] == pytest.approx(reward) and reward != 0.0  # no goal reward, walker's x 2
