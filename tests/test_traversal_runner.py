"""TraversalEnvRunner's lean loop samples the episodes RLlib's env runner samples, and logs them alike."""

import numpy as np
import pytest
import torch
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner
from ray.rllib.utils.metrics import EPISODE_RETURN_MEAN, NUM_ENV_STEPS_SAMPLED_LIFETIME, NUM_EPISODES

from copilot_ray.algorithms.sac.algorithm import GoalSACConfig
from copilot_ray.algorithms.sac.traversal_runner import TraversalEnvRunner

DEPTH = 2


def _config(lean=True, **agent):
    config = (
        GoalSACConfig()
        .environment("maze-point", env_config={"layout": "u-maze"})
        .debugging(seed=5)
        .agent(tau_max=6, **agent)
    )
    config.lean_traversal = lean
    config.validate()
    return config


def _runner(config, cls, plan):
    runner = cls(config=config)
    trees, task_ids = plan
    assert runner.env.unwrapped.call("load_plan", trees, DEPTH, task_ids)[0] == 2 * (2 ** (DEPTH + 1) - 1)
    return runner


@pytest.fixture(scope="module")
def plan():
    env = _config().goal_env
    from copilot_ray import envs

    goal_env = envs.make(env, layout="u-maze").unwrapped
    starts, goals = goal_env.tasks("train")
    rng = np.random.default_rng(0)
    trees = np.stack(
        [np.concatenate([[starts[i]], rng.uniform(0.1, 0.9, (2**DEPTH - 1, 2)), [goals[i]]]) for i in (0, 1)]
    ).astype(np.float32)
    return trees, np.array([0, 1])


def test_validate_picks_the_lean_runner_and_refuses_a_bad_value():
    assert _config(lean=True).env_runner_cls is TraversalEnvRunner
    config = _config(lean=True)
    config.lean_traversal = False
    config.validate()  # switching back drops it again
    assert config.env_runner_cls is None
    bad = GoalSACConfig().environment("maze-point")
    bad.lean_traversal = "yes"
    with pytest.raises(ValueError, match="lean_traversal='yes' is invalid"):
        bad.validate()


@pytest.mark.parametrize("explore", [True, False])
def test_the_lean_loop_samples_rllibs_episodes(plan, explore):
    config = _config()
    rllib, lean = _runner(config, SingleAgentEnvRunner, plan), _runner(config, TraversalEnvRunner, plan)
    lean.set_state(rllib.get_state())  # the same weights
    for call in range(5):  # one sub-task per call: RLlib resets (and seeds) the env at each
        got = {}
        for name, runner in (("rllib", rllib), ("lean", lean)):
            torch.manual_seed(call)  # the same action noise: RLlib's from torch's generator, the lean
            lean.action_noise.set_state(torch.get_rng_state())  # loop's from its own, in that state
            (got[name],) = runner.sample(num_episodes=1, explore=explore)
        want, have = got["rllib"], got["lean"]
        assert len(have) == len(want) > 0
        np.testing.assert_array_equal(have.get_observations(), want.get_observations())
        np.testing.assert_array_equal(have.get_actions(), want.get_actions())
        np.testing.assert_array_equal(have.get_rewards(), want.get_rewards())
        assert (have.is_terminated, have.is_truncated) == (want.is_terminated, want.is_truncated)
        for key, value in want.get_infos(-1).items():  # the sub-task's record the driver reads
            np.testing.assert_array_equal(have.get_infos(-1)[key], value, err_msg=key)
    metrics = {name: runner.get_metrics() for name, runner in (("rllib", rllib), ("lean", lean))}
    for key in (NUM_ENV_STEPS_SAMPLED_LIFETIME, NUM_EPISODES, EPISODE_RETURN_MEAN):
        assert metrics["lean"][key].peek() == pytest.approx(metrics["rllib"][key].peek()), key


def test_one_call_runs_its_sub_tasks_in_order(plan):
    runner = _runner(_config(), TraversalEnvRunner, plan)
    episodes = runner.sample(num_episodes=4, explore=True)
    infos = [e.get_infos(-1) for e in episodes]
    # Task 0's layer 2 (4 sub-tasks, left to right), each continuing where the last one stopped.
    assert [(i["subtask_task"], i["subtask_layer"], i["subtask_index"]) for i in infos] == [
        (0, 2, k) for k in (1, 2, 3, 4)
    ]
    for before, after in zip(episodes, episodes[1:], strict=False):
        np.testing.assert_allclose(after.get_infos(0)["achieved_goal"], before.get_infos(-1)["subtask_end"])
    assert runner.env.unwrapped.call("remaining")[0] == 2 * 7 - 4
    steps = sum(len(e) for e in episodes)
    assert runner.get_metrics()[NUM_ENV_STEPS_SAMPLED_LIFETIME].peek() == steps


def test_a_call_ends_when_the_plan_runs_out_instead_of_stepping_placeholder_episodes(plan):
    """With after_failure="abort_layer" a failed sub-task drops the rest of its layer, so the plan can
    run out before the call's episodes do: the lean loop stops there, and every env step it counts is a
    planned sub-task's (RLlib's loop would step placeholder episodes toward a training goal)."""
    from copilot_ray.algorithms.sac.traversal_channel import INFO_PREFIX, is_idle

    config = _config()
    config.after_failure = "abort_layer"  # (a traversal rule, set on CO-PILOT's config by .copilot())
    config.validate()  # (the rules reach the env through its config, written here)
    runner = _runner(config, TraversalEnvRunner, plan)
    planned = runner.env.unwrapped.call("remaining")[0]
    episodes = runner.sample(num_episodes=planned, explore=True)
    assert runner.env.unwrapped.call("remaining")[0] == 0
    assert episodes and not any(is_idle(e.get_infos(-1)) for e in episodes)
    missed = sum(not e.get_infos(-1)[INFO_PREFIX + "reached"] for e in episodes)
    assert missed and len(episodes) < planned  # (a failure dropped sub-tasks: what the test is about)
    steps = runner.get_metrics()[NUM_ENV_STEPS_SAMPLED_LIFETIME].peek()
    assert steps == sum(len(e) for e in episodes)


def test_the_lean_loop_draws_its_noise_from_its_own_generator_not_torchs(plan):
    """Two runners of one seed sample the same episodes whatever torch's global generator is doing
    in between (a seed stack steps several runners in one process), and a state set back repeats them."""
    config = _config()
    first, second = _runner(config, TraversalEnvRunner, plan), _runner(config, TraversalEnvRunner, plan)
    second.set_state(first.get_state())
    saved = first.action_noise.get_state()
    torch.manual_seed(1)
    (a,) = first.sample(num_episodes=1, explore=True)
    torch.manual_seed(2)
    torch.randn(7)
    (b,) = second.sample(num_episodes=1, explore=True)
    np.testing.assert_array_equal(a.get_actions(), b.get_actions())
    first.env.unwrapped.call("load_plan", *plan[:1], DEPTH, plan[1])
    first.action_noise.set_state(saved)
    (again,) = first.sample(num_episodes=1, explore=True)
    np.testing.assert_array_equal(again.get_actions(), a.get_actions())
    other = _runner(_config().debugging(seed=6), TraversalEnvRunner, plan)
    other.set_state(first.get_state())
    (c,) = other.sample(num_episodes=1, explore=True)
    assert not np.array_equal(c.get_actions()[:3], a.get_actions()[:3])  # another seed, other noise
