"""The HIRO-style hierarchy (``algorithm: hrl``): its goal transition, its off-policy correction on
constructed cases, its settings' rules, a real run's results and resuming from a checkpoint. How well it
learns the demo's open maze (and four-rooms) is a figure of `benchmarks/hrl.py`."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from copilot_ray import keys
from copilot_ray.algorithms.hrl import settings as S
from copilot_ray.algorithms.hrl.hierarchy import (
    SubgoalBox,
    choose_candidates,
    correction_candidates,
    dense_low_reward,
    goal_transition,
)

OPEN_MAZE = {"layout": "empty", "speed": 0.05, "success_radius": 0.1}
# Small nets, a sub-goal every 5 steps within +-0.25 of the maze's width (reachable in 5 steps at speed
# 0.05), 4 high-level updates per high-level transition: learns the open maze in ~2k env steps.
FAST = {
    "tau_max": 40,
    "hrl.c": 5,
    "hrl.subgoal_range": 0.25,
    "low.hidden": [64, 64],
    "high.hidden": [64, 64],
    "high.updates_per_transition": 4.0,
    "env_steps_per_iteration": 500,
    "num_steps_sampled_before_learning_starts": 500,
    "task_batch_size": 4,
    "eval_num_tasks": 40,
}


def _config(seed=0, **changes):
    from copilot_ray.algorithms.hrl.config import HRLConfig
    from copilot_ray.registry import RunContext

    return HRLConfig.from_settings({**FAST, **changes}, RunContext("maze-point", OPEN_MAZE, seed=seed))


# --------------------------------------------------------------------------------------- the maths
def test_the_goal_transition_keeps_the_absolute_subgoal_and_prices_the_low_level():
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 1, (5, 2)).astype(np.float32)
    g = rng.uniform(-0.2, 0.2, (5, 2)).astype(np.float32)
    target = s + g
    for _ in range(4):  # the agent moves; h re-expresses the offset from wherever it is now
        s_next = s + rng.uniform(-0.05, 0.05, s.shape).astype(np.float32)
        g_next = goal_transition(s, g, s_next)
        np.testing.assert_allclose(s_next + g_next, target, atol=1e-6)
        # HIRO's intrinsic reward is minus the distance left to the absolute sub-goal
        np.testing.assert_allclose(dense_low_reward(s, g, s_next), -np.linalg.norm(g_next, axis=1), atol=1e-6)
        s, g = s_next, g_next
    np.testing.assert_allclose(
        goal_transition(np.array([0.2, 0.3]), np.array([0.1, -0.1]), np.array([0.25, 0.3])), [0.05, -0.1]
    )


def test_the_subgoal_box_is_a_fraction_of_the_goal_space_width():
    box = SubgoalBox.from_goal_space(np.array([0.0, -2.0]), np.array([1.0, 2.0]), 0.25)
    np.testing.assert_allclose(box.bound, [0.25, 1.0])
    np.testing.assert_allclose(box.offset(np.array([[1.0, -0.5], [3.0, 0.0]])), [[0.25, -0.5], [0.25, 0.0]])
    np.testing.assert_allclose(box.action(np.array([[0.125, 2.0]])), [[0.5, 1.0]])  # clipped
    with pytest.raises(ValueError, match="finite bounds"):
        SubgoalBox.from_goal_space(np.array([-np.inf]), np.array([np.inf]), 0.1)


def _heading_policy(gain=5.0, std=0.1):
    """A low level that heads for its sub-goal: a ~ N(gain x (sub-goal - achieved), std^2), and its log-prob.
    Flat input = (observation, sub-goal, sub-goal - achieved) as `agent_input: state_goal_delta` composes."""

    def compose(obs, target, ach):
        return np.concatenate([obs, target, target - ach], axis=-1)

    def log_prob(flat, actions):
        mean = np.clip(gain * flat[:, -2:], -1, 1)
        return -0.5 * (((actions - mean) / std) ** 2).sum(axis=-1)

    return compose, log_prob


def test_the_correction_picks_the_candidate_under_which_the_low_level_most_likely_acted():
    compose, log_prob = _heading_policy()
    rng = np.random.default_rng(1)
    b, c = 6, 5
    start = rng.uniform(0.3, 0.7, (b, 2)).astype(np.float32)
    true = rng.uniform(-0.2, 0.2, (b, 2)).astype(np.float32)  # the offset the low level really pursued
    ach = np.zeros((b, c, 2), np.float32)
    act = np.zeros((b, c, 2), np.float32)
    pos = start.copy()
    for j in range(c):  # roll the heading policy (noise-free) towards start + true
        ach[:, j] = pos
        act[:, j] = np.clip(5.0 * (start + true - pos), -1, 1)
        pos = pos + 0.05 * act[:, j]
    obs = ach.copy()
    # Candidates: a wrong stored offset, two decoys, and the true offset at a different index per row.
    cands = rng.uniform(-0.2, 0.2, (b, 4, 2)).astype(np.float32)
    where = np.arange(b) % 4
    cands[np.arange(b), where] = true
    mask = np.ones((b, c), bool)
    best = choose_candidates(cands, start, obs, ach, act, mask, log_prob, compose)
    np.testing.assert_array_equal(best, where)
    # The same choice by brute force over the candidates' summed log-probs.
    for i in range(b):
        scores = [
            log_prob(compose(obs[i], np.broadcast_to(start[i] + g, (c, 2)), ach[i]), act[i]).sum()
            for g in cands[i]
        ]
        assert best[i] == int(np.argmax(scores))

    # Steps past a short segment's end do not count ...
    short = np.ones((b, c), bool)
    short[:, 3:] = False
    act_tail = act.copy()
    act_tail[:, 3:] = 1.0  # whatever was stored there
    np.testing.assert_array_equal(
        choose_candidates(cands, start, obs, ach, act_tail, short, log_prob, compose),
        choose_candidates(cands, start, obs[:, :3], ach[:, :3], act[:, :3], mask[:, :3], log_prob, compose),
    )
    # ... and a tie keeps the stored offset (index 0).
    tied = np.repeat(cands[:, :1], 4, axis=1)
    np.testing.assert_array_equal(choose_candidates(tied, start, obs, ach, act, mask, log_prob, compose), 0)


def test_correction_candidates_are_the_stored_the_achieved_difference_and_samples_around_it():
    box = SubgoalBox(np.array([0.2, 0.2], np.float32))
    stored = np.array([[0.1, -0.1], [0.0, 0.05]], np.float32)
    start = np.array([[0.5, 0.5], [0.1, 0.1]], np.float32)
    end = np.array([[0.55, 0.45], [0.9, 0.1]], np.float32)  # the second moved beyond the box
    cands = correction_candidates(stored, start, end, box, 8, np.random.default_rng(0))
    assert cands.shape == (2, 10, 2)
    np.testing.assert_allclose(cands[:, 0], stored)
    np.testing.assert_allclose(cands[:, 1], [[0.05, -0.05], [0.2, 0.0]], atol=1e-6)  # clipped to the box
    assert (np.abs(cands) <= 0.2 + 1e-7).all()
    assert np.abs(cands[0, 2:] - cands[0, 1]).mean() > 0.01  # spread around the difference


def test_the_algorithm_relabels_sampled_offsets_with_its_current_low_level():
    """On real replay: every corrected action is one of the candidates and scores at least as well under
    the current low level as the stored one."""
    from copilot_ray.algorithms.hrl.algorithm import HRL

    algo = HRL(
        _config(env_steps_per_iteration=200, num_steps_sampled_before_learning_starts=200, eval_interval=0)
    )
    try:
        algo.train()
        batch = {k: v[:64] for k, v in algo.high_buffer._data.items()}
        rng = np.random.default_rng(0)
        actions, kept = algo.correct(batch, rng)
        np.testing.assert_array_equal(actions[kept], batch["actions"][kept])

        def score(a):
            target = batch["start"][:, None] + algo.box.offset(a)[:, None]
            c = batch["seg_obs"].shape[1]
            flat = algo.compose(
                batch["seg_obs"], np.broadcast_to(target, (*target.shape[:1], c, 2)), batch["seg_achieved"]
            )
            lp = algo.low.log_prob(flat.reshape(-1, flat.shape[-1]), batch["seg_actions"].reshape(-1, 2))
            return np.where(batch["seg_mask"], lp.reshape(len(a), c), 0.0).sum(axis=1)

        assert (score(actions) >= score(batch["actions"]) - 1e-3).all()
        assert (~kept).any()  # random warm-up data: the stored offsets rarely explain the actions best
    finally:
        algo.stop()


# ---------------------------------------------------------------------------------------- settings
@pytest.mark.parametrize(
    "setting, value, why",
    [
        ("hrl.c", 0, "an integer >= 1"),
        ("hrl.subgoal_range", 0.0, "a number in (0, 1]"),
        ("hrl.subgoal_range", 1.5, "a number in (0, 1]"),
        ("hrl.low_reward", "shaped", "one of ['dense', 'sparse']"),
        ("hrl.off_policy_correction", "yes", "true or false"),
        ("hrl.num_candidates", -1, "an integer >= 0"),
        ("low.gamma", 1.5, "a number in (0, 1]"),
        ("high.train_batch_size_per_learner", 0, "an integer >= 1"),
        ("high.hidden", [], "a non-empty list"),
        ("env_steps_per_iteration", 0, "an integer >= 1"),
    ],
)
def test_bad_settings_are_refused_naming_the_key_and_the_value(tmp_path, setting, value, why):
    from copilot_ray.sweep_spec import SpecError, load_spec

    spec = {
        "name": "bad",
        "env": {"id": "maze-point", "config": OPEN_MAZE},
        "algorithm": "hrl",
        "config": {setting: value},
        "seeds": [0],
        "stop": {"env_steps": 100, "min_evaluations": 1},
    }
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(SpecError) as err:
        load_spec(path)
    assert f"config.{setting}" in str(err.value) and repr(value) in str(err.value) and why in str(err.value)
    with pytest.raises(ValueError, match=f"{setting}={value!r}".replace("[", r"\[").replace("]", r"\]")):
        _config(**{setting: value})


def test_a_subgoal_period_longer_than_an_episode_is_refused():
    with pytest.raises(ValueError, match=r"hrl.c, tau_max=\{'hrl.c': 50, 'tau_max': 40\} is invalid"):
        _config(**{"hrl.c": 50})
    with pytest.raises(ValueError, match=r"HRLConfig: hrl.nope=1 is invalid: unknown key"):
        _config(**{"hrl.nope": 1})


# ------------------------------------------------------------------------------------- a real run
def test_a_restored_checkpoint_continues_exactly(tmp_path):
    """Tune's save/restore of the trial: the copy continues with the same env-step count, evaluation,
    replay and random streams, so its next iteration equals the original's."""
    import torch

    from copilot_ray.algorithms.hrl.trial import HRLTrial

    cfg = _config(
        env_steps_per_iteration=150,
        num_steps_sampled_before_learning_starts=100,
        eval_num_tasks=10,
        eval_interval=2,
    )
    trial = HRLTrial(config={"algorithm_config": cfg})
    copy = None
    try:
        first = trial.train()
        assert keys.result_value(first, keys.EVAL_FRESH) == 0.0
        assert np.isnan(keys.result_value(first, keys.EVAL_SUCCESS))  # not evaluated yet
        second = trial.train()  # evaluated: the common metric, from the hierarchy's own rollout
        assert keys.result_value(second, keys.EVAL_FRESH) == 1.0
        assert 0.0 <= keys.result_value(second, keys.EVAL_SUCCESS) <= 1.0
        assert keys.result_value(second, keys.EVAL_SUCCESS) == keys.result_value(second, keys.SUCCESS_DIRECT)
        assert 0.0 <= keys.result_value(second, keys.EVAL_RETURN) <= 1.0
        # whole batches of 4 episodes of at most 40 steps, until 150 more env steps per iteration
        assert 300 <= keys.result_value(second, keys.ENV_STEPS) < 2 * (150 + 4 * 40)
        assert 0.0 <= keys.result_value(second, "hrl/correction/original_kept") <= 1.0
        saved = trial.save(str(tmp_path / "ckpt"))
        copy = HRLTrial(config={"algorithm_config": cfg})
        copy.restore(saved)
        assert copy.training_iteration == trial.training_iteration == 2
        # One process holds both: give each the torch stream the checkpoint restored (SAC's sampling).
        restored_stream = torch.get_rng_state()
        a = trial.train()
        torch.set_rng_state(restored_stream)
        b = copy.train()
        for key in (
            keys.ENV_STEPS,
            "env_runners/episode_return_mean",
            "hrl/low/qf_loss",
            "hrl/high/qf_loss",
            keys.EVAL_SUCCESS,
        ):
            assert keys.result_value(a, key) == keys.result_value(b, key), key
        assert keys.result_value(a, keys.EVAL_FRESH) == 0.0  # iteration 3: the last evaluation repeated
        wa = trial.algo.low_group.get_state()["learner"]["rl_module"]
        wb = copy.algo.low_group.get_state()["learner"]["rl_module"]
        for module in wa:
            for name in wa[module]:
                np.testing.assert_array_equal(wa[module][name], wb[module][name])
        assert len(copy.algo.high_buffer) == len(trial.algo.high_buffer)
    finally:
        trial.stop()
        if copy is not None:
            copy.stop()


def test_a_sweep_runs_it_through_tune_into_mlflow(ray_session, tmp_path, capsys):
    """`algorithm: hrl` from a spec file: a FINISHED MLflow run with copilot/eval/success and
    copilot/eval/return logged against env steps."""
    import mlflow

    from copilot_ray.keys import ALGORITHM_TAG, ROLE_TAG, ROLE_TRIAL
    from copilot_ray.sweep import main
    from copilot_ray.sweep_spec import load_spec

    spec = {
        "name": "hrl_sweep",
        "experiment": "hrl",
        "env": {"id": "maze-point", "config": OPEN_MAZE},
        "algorithm": "hrl",
        "config": {
            **FAST,
            "env_steps_per_iteration": 200,
            "eval_num_tasks": 10,
            "high.updates_per_transition": 1.0,
        },
        "seeds": [0],
        "stop": {"iterations": 2, "min_evaluations": 1},
        "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
        "tracking": {"storage": str(tmp_path / "results"), "uri": f"sqlite:///{tmp_path}/hrl.db"},
    }
    path = tmp_path / "hrl.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    assert main([str(path)]) == 0
    assert "hrl on maze-point" in capsys.readouterr().out

    client = mlflow.MlflowClient(load_spec(path).tracking.uri)
    exp = client.get_experiment_by_name("hrl")
    runs = [r for r in client.search_runs([exp.experiment_id]) if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    assert [r.data.tags[ALGORITHM_TAG] for r in runs] == ["hrl"] and runs[0].info.status == "FINISHED"
    for key in (keys.EVAL_SUCCESS, keys.EVAL_RETURN):
        history = client.get_metric_history(runs[0].info.run_id, key)
        assert len(history) == 2 and all(0.0 <= m.value <= 1.0 for m in history)
        assert history[1].step > history[0].step >= 200  # MLflow steps are env steps
    # Its own diagnostics reach MLflow too (they were once dropped by the tracked-namespace filter).
    assert len(client.get_metric_history(runs[0].info.run_id, S.SUBGOAL_REACHED)) == 2
    assert client.get_metric_history(runs[0].info.run_id, S.LOW_QF_LOSS)  # once learning has started
