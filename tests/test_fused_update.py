"""The fused SAC update (`GCSACTorchLearner.update_from_replay`, `SACStep` at N = 1) against RLlib's path.

The fused step must be RLlib's step (`update(batch=...)` through `_uncompiled_update`) for the same
batch, parameters and noise (the step draws its noise from its Philox stream; RLlib's path is handed
the same numbers): losses, gradients, new parameters, targets, log alpha and optimizer state. A
non-finite step must change nothing and be counted; a checkpoint must carry the optimizer state, log
alpha, the noise stream and the replay, and continue identically. All on the CPU (CI has no GPU).
"""

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.metrics import ALL_MODULES

from copilot_ray.algorithms.gc_sac import (
    NONFINITE_SKIPPED_KEY,
    FlatTransitionBuffer,
    gc_sac_settings,
    make_train_batch,
    use_fast_learner,
)
from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.sac_step import FINITE, NOISE_STREAM, TOTAL_LOSS, with_seed_axis

OBS_SPACE = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
ACT_SPACE = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
COLUMNS = ("obs", "new_obs", "actions", "rewards", "terminateds")


def _learner_group(critic_loss="huber"):
    cfg = SACConfig().environment(observation_space=OBS_SPACE, action_space=ACT_SPACE).debugging(seed=0)
    cfg.training(tau=0.05)  # a large tau: a wrong target update shows
    return use_fast_learner(
        cfg, hidden=(32, 32), torch_threads=1, critic_loss=critic_loss
    ).build_learner_group()


def _twins(critic_loss="huber"):
    """Two learner groups with the same parameters and optimizer state."""
    a, b = _learner_group(critic_loss), _learner_group(critic_loss)
    b.set_state(a.get_state())
    return a, b


def _columns(n=64, seed=0, reward=-1.0):
    rng = np.random.default_rng(seed)
    obs = rng.uniform(0, 1, (n, 4)).astype(np.float32)
    return {
        "obs": obs,
        "new_obs": np.clip(obs + rng.normal(0, 0.02, obs.shape), 0, 1).astype(np.float32),
        "actions": rng.uniform(-1, 1, (n, 2)).astype(np.float32),
        "rewards": np.full(n, reward, np.float32),
        "terminateds": rng.random(n) < 0.2,
    }


def _snapshot(learner_group):
    """Every tensor a step may change: module (online and target nets), log alpha, optimizer state."""
    learner = learner_group._learner
    out = {
        f"module/{k}": v.detach().clone() for k, v in learner.module[DEFAULT_MODULE_ID].state_dict().items()
    }
    out["log_alpha"] = learner.curr_log_alpha[DEFAULT_MODULE_ID].detach().clone()
    for name, optimizer in learner.get_optimizers_for_module(DEFAULT_MODULE_ID):
        for i, state in enumerate(optimizer.state.values()):
            for key, value in state.items():
                out[f"{name}/{i}/{key}"] = value.detach().clone()
    return out


def _grads(learner_group):
    module = learner_group._learner.module[DEFAULT_MODULE_ID]
    return {n: p.grad.clone() for n, p in module.named_parameters() if p.grad is not None}


def _step_grads(learner_group):
    """The fused step's gradients by module parameter name: each parameter is a view of the step's
    row, its gradient the same columns of the step's gradient row."""
    step = learner_group._learner.fused_step()
    module = learner_group._learner.module[DEFAULT_MODULE_ID]
    row = step.flat[0]
    out = {}
    for name, p in module.named_parameters():
        if name.startswith("target_"):
            continue
        at = (p.data_ptr() - row.data_ptr()) // row.element_size()
        assert 0 <= at < row.numel(), name  # the parameter lives in the step's row
        out[name] = step.flat_grad[0, at : at + p.numel()].view(p.shape).clone()
    return out


class HandedNoise:
    """torch's Normal sampling replaced by given standard-normal draws, in order (RLlib's module
    draws the current actions' noise by `rsample`, the next actions' by `sample`)."""

    def __init__(self, monkeypatch):
        self.queue = []
        handed = self

        def rsample(dist, sample_shape=torch.Size()):
            return dist.loc + handed.queue.pop(0) * dist.scale

        def sample(dist, sample_shape=torch.Size()):
            with torch.no_grad():
                return rsample(dist, sample_shape)

        monkeypatch.setattr(torch.distributions.Normal, "rsample", rsample)
        monkeypatch.setattr(torch.distributions.Normal, "sample", sample)

    def hand_next_draws_of(self, step, batch_size, action_dim=2):
        """Queues what `step` will draw in its next call (a twin of its stream at its counter)."""
        twin = PhiloxStreams([0], NOISE_STREAM)
        twin.counters.copy_(step.noise.counters)
        draws = twin.normal((2, batch_size, action_dim))[0]
        self.queue[:] = [draws[0], draws[1]]


def _assert_same(want, got, **tolerance):
    assert want.keys() == got.keys()
    for key in want:
        torch.testing.assert_close(got[key], want[key], msg=lambda m, k=key: f"{k}: {m}", **tolerance)


@pytest.mark.parametrize("critic_loss", ["huber", "mse"])
def test_the_fused_step_is_rllibs_step_for_the_same_batch(critic_loss, monkeypatch):
    rllib_path, fused_path = _twins(critic_loss)
    fused = fused_path._learner.fused_step()
    cols = _columns()
    batch = with_seed_axis({k: torch.as_tensor(v) for k, v in cols.items()})
    before = _snapshot(rllib_path)
    noise = HandedNoise(monkeypatch)
    for _ in range(3):  # three steps: Adam's moments and the targets carry over
        noise.hand_next_draws_of(fused, len(cols["obs"]))  # the same reparameterisation noise on both paths
        result = rllib_path.update(
            batch=make_train_batch(cols),
            minibatch_size=len(cols["obs"]),
            num_epochs=1,
            shuffle_batch_per_epoch=False,
        )[0][DEFAULT_MODULE_ID]
        assert not noise.queue  # RLlib's path took both draws
        stats = fused.step(batch)
        assert bool(stats[FINITE])
        for key in (
            "qf_loss",
            "qf_twin_loss",
            "policy_loss",
            "alpha_loss",
            "qf_mean",
            "td_error_mean",
            "logps",
        ):
            assert stats[key].item() == pytest.approx(float(result[key].peek()), rel=1e-6, abs=1e-7), key
        assert stats[TOTAL_LOSS].item() == pytest.approx(
            float(result["total_loss"].peek()), rel=1e-6, abs=1e-7
        )
        _assert_same(_grads(rllib_path), _step_grads(fused_path), rtol=1e-6, atol=1e-7)
    after = _snapshot(rllib_path)
    _assert_same(after, _snapshot(fused_path), rtol=1e-6, atol=1e-7)
    # It trained: the online critic, the targets and log alpha moved; each Adam took three steps.
    for key in ("module/qf.net.mlp.0.weight", "module/target_qf.net.mlp.0.weight", "log_alpha"):
        assert not torch.equal(before[key], after[key]), key
    steps = [v.item() for k, v in after.items() if k.endswith("/step")]
    assert len(steps) == 12 + 6 + 1 and set(steps) == {3.0}  # twin critics, actor, log alpha


def test_update_from_replay_samples_its_batch_inside_the_step_and_logs_as_rllib_does():
    by_hand, from_replay = _twins()
    replays = [FlatTransitionBuffer(100, device=from_replay._learner.device) for _ in range(2)]
    for replay in replays:  # twins: each samples its own rows from the same stream
        replay.add(_columns(n=40))
    fused = by_hand._learner.fused_step()
    for _ in range(4):
        fused.step(replays[0].sample(16))  # [1, 16, ...]: one seed's batch
    result = from_replay._learner.update_from_replay(
        replays[1], 4, 16, {"num_env_steps_sampled_lifetime": 40}
    )
    _assert_same(_snapshot(by_hand), _snapshot(from_replay), rtol=0, atol=0)
    module = result[DEFAULT_MODULE_ID]
    assert module["num_target_updates"].peek() == 4
    assert module["num_module_steps_trained"].peek() == 4 * 16
    assert result[ALL_MODULES]["num_env_steps_trained"].peek() == 4 * 16
    assert np.isfinite(module["qf_loss"].peek()) and "qf_learning_rate" in module
    assert NONFINITE_SKIPPED_KEY not in result[ALL_MODULES]  # nothing skipped: nothing logged, as before


def test_a_nonfinite_step_changes_nothing_and_is_counted_on_the_device():
    learner_group = _learner_group()
    learner = learner_group._learner
    replay = FlatTransitionBuffer(100, device=learner.device)
    replay.add(_columns(n=40))
    learner.update_from_replay(replay, 2, 16)  # Adam's moments exist and are not zero
    before = _snapshot(learner_group)

    poisoned = FlatTransitionBuffer(100, device=learner.device)
    poisoned.add(_columns(n=40, reward=np.nan))
    result = learner.update_from_replay(poisoned, 3, 16)
    assert result[ALL_MODULES][NONFINITE_SKIPPED_KEY].peek() == 3
    assert result[DEFAULT_MODULE_ID]["num_target_updates"].peek() == 0  # this call's: none moved
    # Online and target nets, log alpha, Adam's moments and step counts: exactly as before.
    _assert_same(before, _snapshot(learner_group), rtol=0, atol=0)
    assert learner.fused_step().skipped.item() == 3

    # One poisoned row in an otherwise clean batch is enough to skip, and the guard lets clean steps pass.
    batch = with_seed_axis({k: torch.as_tensor(v) for k, v in _columns(n=16).items()})
    batch["rewards"][0, 5] = float("nan")
    assert not bool(learner.fused_step().step(batch)[FINITE])
    _assert_same(before, _snapshot(learner_group), rtol=0, atol=0)
    result = learner.update_from_replay(replay, 1, 16)
    # The counter is read once per call: the direct step's skip shows in the next call's results.
    assert result[ALL_MODULES][NONFINITE_SKIPPED_KEY].peek() == 1
    assert learner.fused_step().skipped.item() == 4
    assert not torch.equal(
        before["module/qf.net.mlp.0.weight"], _snapshot(learner_group)["module/qf.net.mlp.0.weight"]
    )


def test_a_checkpoint_restores_optimizer_state_log_alpha_noise_and_the_replay_then_continues_identically(
    tmp_path,
):
    original = _learner_group()
    replay = FlatTransitionBuffer(64, device=original._learner.device)
    replay.add(_columns(n=50, seed=1))
    replay.add(_columns(n=30, seed=2))  # wraps around: the write pointer matters
    original._learner.update_from_replay(replay, 5, 16)
    original.save_to_path(tmp_path / "learner_group")
    replay_state = replay.get_state()

    restored = _learner_group()
    restored.restore_from_path(tmp_path / "learner_group")
    restored_replay = FlatTransitionBuffer(1, device=restored._learner.device)
    restored_replay.set_state(replay_state)
    _assert_same(
        _snapshot(original), _snapshot(restored), rtol=0, atol=0
    )  # optimizer state and log alpha too
    for key, rows in replay.transitions().items():
        np.testing.assert_array_equal(restored_replay.transitions()[key], rows)

    results = []
    for learner_group, buffer in ((original, replay), (restored, restored_replay)):
        results.append(learner_group._learner.update_from_replay(buffer, 3, 16)[DEFAULT_MODULE_ID])
        buffer.add(_columns(n=5, seed=3))
    _assert_same(_snapshot(original), _snapshot(restored), rtol=0, atol=0)
    assert results[0]["qf_loss"].peek() == results[1]["qf_loss"].peek()
    np.testing.assert_array_equal(restored_replay.transitions()["obs"], replay.transitions()["obs"])


@pytest.mark.parametrize("key", ["fused_update", "cuda_graph", "compile_update"])
def test_a_knob_that_is_not_a_bool_is_refused_naming_it(key):
    config = use_fast_learner(SACConfig())
    config.learner_config_dict["gc_sac"][key] = "yes"
    with pytest.raises(ValueError, match=rf"\['{key}'\] must be True or False, got 'yes'"):
        gc_sac_settings(config)


def test_an_empty_replay_is_refused():
    learner = _learner_group()._learner
    with pytest.raises(ValueError, match="the replay is empty"):
        learner.update_from_replay(FlatTransitionBuffer(8, device=learner.device), 1, 4)


def test_an_agents_learner_options_are_checked_by_name():
    from copilot_ray.algorithms.sac.algorithm import GoalSACConfig

    config = GoalSACConfig().environment("maze-point")
    config.fast_learner_options = {"fused": False}
    with pytest.raises(ValueError, match=r"fast_learner_options\['fused'\]=False is invalid: known keys"):
        config.validate()
    # The path itself is a setting (a sweep can run both), not one of these options.
    config = GoalSACConfig().environment("maze-point")
    config.fast_learner_options = {"fused_update": False}
    with pytest.raises(ValueError, match=r"\['fused_update'\]=False is invalid.*config.agent\(fused_update"):
        config.validate()
    config = GoalSACConfig().environment("maze-point").agent(fused_update=0)
    with pytest.raises(ValueError, match=r"fused_update=0 is invalid: must be true or false"):
        config.validate()
    config = GoalSACConfig().environment("maze-point")
    config.fast_learner_options = {"cuda_graph": 1}
    with pytest.raises(ValueError, match=r"\['cuda_graph'\] must be True or False, got 1"):
        config.validate()
    config = GoalSACConfig().environment("maze-point").agent(fused_update=False)
    config.validate()
    assert gc_sac_settings(config)["fused_update"] is False
    default = GoalSACConfig().environment("maze-point")
    default.validate()
    assert gc_sac_settings(default)["fused_update"] is True
