"""GC-SAC module/learner: Bellman targets by hand, a real local LearnerGroup, checkpoints, NaN guard."""

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.distribution.torch.torch_distribution import TorchSquashedGaussian
from ray.rllib.utils.metrics import ALL_MODULES

import copilot_ray.algorithms.gc_sac.losses as gc_losses
from copilot_ray.algorithms.gc_sac import (
    NONFINITE_SKIPPED_KEY,
    FlatTransitionBuffer,
    GCSACTorchLearner,
    GCSACTorchRLModule,
    GradientStepSchedule,
    count_parameters,
    gc_sac_settings,
    host_sampler,
    make_train_batch,
    update_from_buffer,
    use_fast_learner,
)

OBS_SPACE = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
ACT_SPACE = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)


def _config(hidden=(32, 32), **training):
    cfg = SACConfig().environment(observation_space=OBS_SPACE, action_space=ACT_SPACE).debugging(seed=0)
    if training:
        cfg.training(**training)
    return use_fast_learner(cfg, hidden=hidden, torch_threads=1)


def _buffer(n=512, seed=0):
    rng = np.random.default_rng(seed)
    obs = rng.uniform(0, 1, (n, 4)).astype(np.float32)
    buf = FlatTransitionBuffer(capacity=2 * n)
    buf.add(
        {
            "obs": obs,
            "new_obs": np.clip(obs + rng.normal(0, 0.02, obs.shape), 0, 1),
            "actions": rng.uniform(-1, 1, (n, 2)),
            "rewards": -np.ones(n),
            "terminateds": rng.random(n) < 0.1,
        }
    )
    return buf


def _mlp(layers, x):
    """Hand forward pass through an RLlib TorchMLP's nn.Sequential (Linear/ReLU)."""
    for layer in layers:
        x = torch.relu(x) if isinstance(layer, torch.nn.ReLU) else x @ layer.weight.T + layer.bias
    return x


def test_sb3_shaped_parameter_count():
    cfg = _config(hidden=(256, 256))
    module = cfg.get_rl_module_spec().build()
    assert isinstance(module, GCSACTorchRLModule)
    module.make_target_networks()
    counts = count_parameters(module)
    # SB3 SAC for obs 4 / act 2 / [256, 256]: actor 68,100 + 2 critics 135,682 + 2 targets 135,682.
    assert counts == {"trainable": 203_782, "target": 135_682, "total": 339_464}
    # The env-runner (inference-only) module has the actor only and acts.
    spec = cfg.get_rl_module_spec()
    spec.inference_only = True
    small = spec.build()
    assert count_parameters(small)["total"] == 68_100
    out = small.forward_exploration({"obs": torch.zeros(3, 4)})
    assert out["action_dist_inputs"].shape == (3, 4)


def test_critic_target_matches_hand_computed_bellman_target(monkeypatch):
    gamma, alpha = 0.9, 0.3
    lg = _config(gamma=gamma, initial_alpha=alpha).build_learner_group()
    learner = lg._learner
    assert isinstance(learner, GCSACTorchLearner)
    module = learner.module[DEFAULT_MODULE_ID]
    # Make the online critics differ from the targets, so using the wrong nets would show.
    with torch.no_grad():
        for p in list(module.qf_encoder.parameters()) + list(module.qf_twin.parameters()):
            p.add_(0.5 * torch.randn_like(p))

    g = torch.Generator().manual_seed(0)
    n = 8
    obs = torch.rand(n, 4, generator=g)
    batch = {
        "obs": obs,
        "new_obs": torch.rand(n, 4, generator=g),
        "actions": torch.rand(n, 2, generator=g) * 2 - 1,
        "rewards": torch.linspace(-1.0, 1.0, n),
        "terminateds": torch.tensor([0, 1, 0, 0, 1, 0, 0, 1], dtype=torch.bool),
    }
    a_next = torch.rand(n, 2, generator=g) * 1.6 - 0.8  # fixed a' (interior: exact log-probs)

    # Fix a' ~ pi(.|s'): the next-state sample is the only `sample_and_logp` call in forward_train.
    def fixed_sample_and_logp(self, *, sample_shape=None):
        return a_next.clone(), self.logp(a_next)

    monkeypatch.setattr(TorchSquashedGaussian, "sample_and_logp", fixed_sample_and_logp)
    captured = {}
    real_target = gc_losses.bellman_target

    def recording_target(*args, **kwargs):
        captured["y"] = real_target(*args, **kwargs)
        return captured["y"]

    monkeypatch.setattr(gc_losses, "bellman_target", recording_target)

    fwd = learner.module.forward_train({DEFAULT_MODULE_ID: batch})
    learner.compute_losses(fwd_out=fwd, batch={DEFAULT_MODULE_ID: batch})

    with torch.no_grad():
        # log pi(a'|s') by hand: Gaussian in pre-tanh space minus the tanh Jacobian.
        logits = _mlp(module.pi.net.mlp, _mlp(module.pi_encoder.net.mlp, batch["new_obs"]))
        mean, log_std = logits.chunk(2, dim=-1)
        std = log_std.clamp(-5.0, 2.0).exp()
        u = torch.atanh(a_next)
        normal_logp = (-0.5 * ((u - mean) / std) ** 2 - std.log() - 0.5 * math.log(2 * math.pi)).sum(-1)
        logp = normal_logp - torch.log(1 - a_next**2).sum(-1)
        # min of the twin *target* critics at (s', a').
        x = torch.cat([batch["new_obs"], a_next], -1)
        q1 = _mlp(module.target_qf.net.mlp, _mlp(module.target_qf_encoder.net.mlp, x)).squeeze(-1)
        q2 = _mlp(module.target_qf_twin.net.mlp, _mlp(module.target_qf_twin_encoder.net.mlp, x)).squeeze(-1)
        done = batch["terminateds"].float()
        expected = batch["rewards"] + gamma * (1 - done) * (torch.min(q1, q2) - alpha * logp)

    torch.testing.assert_close(captured["y"], expected, rtol=1e-4, atol=1e-4)
    # Terminal transitions bootstrap nothing.
    torch.testing.assert_close(captured["y"][done.bool()], batch["rewards"][done.bool()])


def test_learner_group_update_from_buffer_and_checkpoint(tmp_path):
    cfg = _config(tau=0.01)
    lg = cfg.build_learner_group()
    learner = lg._learner
    module = learner.module[DEFAULT_MODULE_ID]
    buf = _buffer()
    before = {k: v.clone() for k, v in module.state_dict().items()}

    results = update_from_buffer(lg, host_sampler(buf), num_gradient_steps=4, batch_size=32, timesteps=512)
    res = results[0][DEFAULT_MODULE_ID]
    for key in ("qf_loss", "policy_loss", "alpha_value", "qf_twin_loss", "num_target_updates"):
        assert key in res, key
    assert res["num_target_updates"].peek() == 4  # targets move once per gradient step
    assert res["num_module_steps_trained"].peek() == 4 * 32
    after = module.state_dict()
    for name in (
        "pi_encoder.net.mlp.0.weight",
        "qf_encoder.net.mlp.0.weight",
        "target_qf_encoder.net.mlp.0.weight",
    ):
        assert not torch.equal(before[name], after[name]), name
    # Polyak targets: strictly between the old target and the new online weights.
    old_t, new_t = before["target_qf.net.mlp.0.weight"], after["target_qf.net.mlp.0.weight"]
    online = after["qf.net.mlp.0.weight"]
    assert (new_t - old_t).abs().max() < (online - old_t).abs().max()

    # Checkpoint round trip through RLlib's Checkpointable API.
    lg.save_to_path(tmp_path / "lg")
    lg2 = _config(tau=0.01).build_learner_group()
    lg2.restore_from_path(tmp_path / "lg")
    s1, s2 = lg.get_state(), lg2.get_state()
    w1 = s1["learner"]["rl_module"][DEFAULT_MODULE_ID]
    w2 = s2["learner"]["rl_module"][DEFAULT_MODULE_ID]
    assert w1.keys() == w2.keys()
    for k in w1:
        np.testing.assert_array_equal(w1[k], w2[k])
    # Both continue identically from the restored state (same batch: the replay's stream rewound; same
    # torch seed).
    stream = buf.get_state()
    torch.manual_seed(1)
    r1 = update_from_buffer(lg, host_sampler(buf), 2, 32, 600)[0][DEFAULT_MODULE_ID]
    buf.set_state(stream)
    torch.manual_seed(1)
    r2 = update_from_buffer(lg2, host_sampler(buf), 2, 32, 600)[0][DEFAULT_MODULE_ID]
    assert r1["qf_loss"].peek() == pytest.approx(r2["qf_loss"].peek(), rel=1e-5)


def test_nan_batch_is_skipped_without_touching_weights():
    lg = _config().build_learner_group()
    learner = lg._learner
    module = learner.module[DEFAULT_MODULE_ID]
    buf = _buffer()
    cols = {k: v.copy() for k, v in host_sampler(buf)(64).items()}
    cols["rewards"][3] = np.nan
    before = {k: v.clone() for k, v in module.state_dict().items()}
    alpha_before = learner.curr_log_alpha[DEFAULT_MODULE_ID].detach().clone()
    # One minibatch (64 of 64) holding a NaN reward: the step is skipped entirely.
    res = lg.update(
        batch=make_train_batch(cols), minibatch_size=64, num_epochs=1, shuffle_batch_per_epoch=False
    )
    assert res[0][ALL_MODULES][NONFINITE_SKIPPED_KEY].peek() == 1
    after = module.state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)  # online and target nets untouched
    assert torch.equal(alpha_before, learner.curr_log_alpha[DEFAULT_MODULE_ID].detach())
    # A clean batch afterwards trains normally.
    update_from_buffer(lg, host_sampler(buf), 1, 64, 64)
    assert not torch.equal(before["qf.net.mlp.0.weight"], module.state_dict()["qf.net.mlp.0.weight"])


def test_stock_learner_accepts_the_same_batch_with_weights_and_n_step():
    cfg = SACConfig().environment(observation_space=OBS_SPACE, action_space=ACT_SPACE)
    cfg.rl_module(model_config={"fcnet_hiddens": [16, 16]})
    lg = cfg.build_learner_group()
    res = update_from_buffer(lg, host_sampler(_buffer()), 2, 32, 100, with_weights_and_n_step=True)
    assert "qf_loss" in res[0][DEFAULT_MODULE_ID]


def test_settings_and_gradient_step_schedule():
    cfg = use_fast_learner(SACConfig(), updates_per_env_step=0.25, critic_loss="mse")
    s = gc_sac_settings(cfg)
    assert s["updates_per_env_step"] == 0.25 and s["critic_loss"] == "mse" and s["torch_threads"] == 2
    assert cfg.torch_skip_nan_gradients is True
    with pytest.raises(ValueError):
        use_fast_learner(SACConfig(), critic_loss="l1")
    sched = GradientStepSchedule(0.25, learning_starts=4)
    steps = [sched.on_env_steps(1) for _ in range(12)]
    assert steps == [0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1]  # 8 eligible steps -> 2 updates
    assert GradientStepSchedule(2.0).on_env_steps(16) == 32
    sched2 = GradientStepSchedule()
    sched2.set_state(sched.get_state())
    assert sched2.on_env_steps(4) == sched.on_env_steps(4) == 1
