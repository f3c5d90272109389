"""One measuring protocol for every agent (copilot_ray.evaluation.AgentEvaluation): two methods' rollout
machinery (the lockstep evaluation GoalSAC and PPO use, HRL's two-level episodes) through it give the
figures a hand-written loop gives on the same tasks. No Ray."""

import numpy as np
import pytest

from copilot_ray import keys
from copilot_ray.algorithms.hrl.hierarchy import SubgoalBox
from copilot_ray.algorithms.hrl.rollout import run_episodes
from copilot_ray.envs import make
from copilot_ray.envs.goal_observation import flat_observation
from copilot_ray.evaluation import AgentEvaluation, evaluate_copilot

ENV = {"layout": "four-rooms", "num_validation_tasks": 6, "num_test_tasks": 5, "speed": 0.01}
STEPS = 60  # per task: some tasks are reached, some are not, some run into a wall
R = 2.0  # the task reward the return is counted in


def straight(obs):
    """Heads for the goal (flat input: position, goal): full speed, no learning."""
    d = obs[:, 2:4] - obs[:, :2]
    return np.clip(d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9), -1, 1).astype(np.float32)


def reference(starts, goals):
    """The hand-written loop: each task alone, step by step; success = reached with no collision."""
    env = make("maze-point", **ENV)
    success, reached = [], []
    for s, g in zip(starts, goals, strict=True):
        obs, _ = env.reset(options={"start": s, "goal": g})
        hit = done = False
        for _ in range(STEPS):
            flat = flat_observation(obs["observation"][None], g[None], None)
            obs, _, done, _, info = env.step(straight(flat)[0])
            hit |= bool(info["collision"])
            if done:
                break
        success.append(done and not hit)
        reached.append(done)
    return float(np.mean(success)), float(np.mean(reached))


def lockstep(evaluation, split):
    """GoalSAC's and PPO's rollouts: `evaluate_copilot`, the agent alone."""
    starts, goals = evaluation.tasks[split]
    policies = dict.fromkeys(evaluation.action_seeds(split, 3, 5), straight)
    result = evaluate_copilot(
        goal_env_id="maze-point",
        goal_env_config=ENV,
        policies=policies,
        planner=None,
        starts=starts,
        goals=goals,
        depth=0,
        tau_max=STEPS,
    )
    return result.by_action


def two_level(evaluation, split):
    """HRL's rollouts: its two-level episodes, the high level proposing the goal itself (its offset from
    where the agent is, inside the box), the low level heading straight for the proposal."""
    starts, goals = evaluation.tasks[split]
    envs = [make("maze-point", **ENV) for _ in starts]
    box = SubgoalBox.from_goal_space(np.zeros(2), np.ones(2), 1.0)

    def high(x):
        return box.action(x[:, 2:4] - x[:, :2])

    by_action = {}
    for action in evaluation.action_seeds(split, 3, 5):
        episodes = run_episodes(
            envs,
            starts,
            goals,
            high,
            straight,
            box,
            c=1,
            tau_max=STEPS,
            compose=lambda o, g, a: flat_observation(o, g, None),
        )
        by_action[action] = {
            keys.eval_leaf(keys.SUCCESS_DIRECT): float(np.mean([e.success for e in episodes])),
            keys.eval_leaf(keys.REACHED_DIRECT): float(np.mean([e.terminated for e in episodes])),
        }
    return by_action


@pytest.mark.parametrize("rollouts", [lockstep, two_level])
def test_two_methods_rollouts_give_the_reference_loops_figures(rollouts):
    env = make("maze-point", **ENV).unwrapped
    evaluation = AgentEvaluation(
        env, num_tasks=4, eval_action="deterministic", every_iterations=1, task_reward=R
    )
    assert evaluation.num_tasks == 4 and len(evaluation.tasks["validation"][0]) == 4
    figures = {}
    for split in ("validation", "test"):
        figures.update(evaluation.figures(split, rollouts(evaluation, split), env_steps=1000))
    for split, prefix in (("validation", keys.VALIDATION_PREFIX), ("test", keys.EVAL_PREFIX)):
        success, reached = reference(*evaluation.tasks[split])
        assert figures[prefix + "success"] == pytest.approx(success)
        assert figures[prefix + "success_direct"] == pytest.approx(success)
        assert figures[prefix + "success_planned"] == pytest.approx(success)  # no plan: the agent alone
        assert figures[prefix + "success_auc"] == pytest.approx(success)  # one evaluation: its value
        assert figures[prefix + "return"] == pytest.approx(R * reached)
    assert 0 < figures[keys.EVAL_SUCCESS] < 1 or 0 < figures[keys.validation_key(keys.EVAL_SUCCESS)] < 1
    # Both action modes on the test tasks, the headline alone on the validation tasks.
    assert keys.eval_by_action(keys.SUCCESS_DIRECT, "sampled") in figures
    assert not any(k.startswith(keys.VALIDATION_PREFIX + "sampled") for k in figures)


def test_every_method_samples_from_the_same_seeds_and_curves_accumulate():
    env = make("maze-point", **ENV).unwrapped
    evaluation = AgentEvaluation(env, num_tasks=10, eval_action="sampled", every_iterations=1)
    assert evaluation.num_tasks == 5  # the fewer of the two sets' sizes
    assert evaluation.action_seeds("test", 3, 5) == {"sampled": 8, "deterministic": None}
    assert evaluation.action_seeds("validation", None, 2) == {"sampled": 2}
    by_action = {"sampled": {"success_direct": 0.2, "reached_direct": 0.4}}
    evaluation.figures("validation", by_action, 1000)
    by_action = {"sampled": {"success_direct": 0.6, "reached_direct": 0.8}}
    second = evaluation.figures("validation", by_action, 3000)
    assert second[keys.validation_key(keys.EVAL_SUCCESS_AUC)] == pytest.approx(0.4)  # trapezoid / span
    restored = AgentEvaluation(env, num_tasks=10, eval_action="sampled", every_iterations=1)
    restored.set_state(evaluation.get_state())
    assert restored.curves["validation"].values == [0.2, 0.6]
    with pytest.raises(ValueError, match="eval_action='best' is invalid"):
        AgentEvaluation(env, num_tasks=1, eval_action="best", every_iterations=1)
