"""Seeds stacked in one update (`seed_stack.StackedSACStep`) against each seed's own fused step.

A stack of seeds {0, 1, 2} must give every seed the update its one-seed `FusedSACStep` gives it for the
same batch and the same noise stream: losses, new parameters, target critics and log alpha, over
several steps (Adam's moments and the targets carry over). A seed whose gradient is not finite must
stay where it was while the others step. All on the CPU.
"""

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray.algorithms.gc_sac import use_fast_learner
from copilot_ray.algorithms.gc_sac.fused_step import FINITE
from copilot_ray.algorithms.gc_sac.seed_stack import (
    NETWORKS,
    StackedSAC,
    StackedSACStep,
    _linear_layers,
    stack_batches,
)

OBS_SPACE = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
ACT_SPACE = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
SEEDS = (0, 1, 2)


def _learner(seed, critic_loss="huber"):
    cfg = SACConfig().environment(observation_space=OBS_SPACE, action_space=ACT_SPACE).debugging(seed=seed)
    cfg.training(tau=0.05, actor_lr=3e-4, critic_lr=1e-3, alpha_lr=2e-3)  # distinct rates: a mix-up shows
    return (
        use_fast_learner(cfg, hidden=(32, 32), torch_threads=1, critic_loss=critic_loss)
        .build_learner_group()
        ._learner
    )


def _batch(seed, n=64, reward=-1.0):
    rng = np.random.default_rng(100 + seed)
    obs = rng.uniform(0, 1, (n, 4)).astype(np.float32)
    cols = {
        "obs": obs,
        "new_obs": np.clip(obs + rng.normal(0, 0.02, obs.shape), 0, 1).astype(np.float32),
        "actions": rng.uniform(-1, 1, (n, 2)).astype(np.float32),
        "rewards": np.full(n, reward, np.float32),
        "terminateds": rng.random(n) < 0.2,
    }
    return {k: torch.as_tensor(v) for k, v in cols.items()}


def _stack_of(learners, critic_loss="huber"):
    modules = [learner.module[DEFAULT_MODULE_ID].unwrapped() for learner in learners]
    agents = StackedSAC.from_modules(
        modules, [learner.curr_log_alpha[DEFAULT_MODULE_ID] for learner in learners]
    )
    config = learners[0].config.get_config_for_module(DEFAULT_MODULE_ID)
    lrs = {"qf": config.critic_lr, "policy": config.actor_lr, "alpha": config.alpha_lr}
    generators = [torch.Generator() for _ in learners]
    step = StackedSACStep(
        agents,
        lrs,
        learners[0].target_entropy[DEFAULT_MODULE_ID],
        gamma=config.gamma,
        tau=config.tau,
        critic_loss=critic_loss,
        generators=generators,
    )
    return step, generators


def _assert_seed_matches(stacked, learner, i):
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    for name, encoder, head in NETWORKS:
        layers = _linear_layers(getattr(module, encoder), getattr(module, head))
        for k, (layer, (weight, bias)) in enumerate(zip(layers, stacked.agents.nets[name], strict=True)):
            torch.testing.assert_close(
                weight[i], layer.weight, rtol=1e-5, atol=1e-6, msg=f"{name}[{k}] seed {i}"
            )
            torch.testing.assert_close(
                bias[i], layer.bias, rtol=1e-5, atol=1e-6, msg=f"{name}[{k}] bias seed {i}"
            )
    torch.testing.assert_close(
        stacked.agents.log_alpha[i], learner.curr_log_alpha[DEFAULT_MODULE_ID], rtol=1e-6, atol=1e-7
    )


def _run(learners, batches, steps=3, critic_loss="huber"):
    """`steps` one-seed fused steps per learner and the same steps stacked; the stacked step."""
    stacked, generators = _stack_of(learners, critic_loss)
    for t in range(steps):
        stats = []
        for i, learner in enumerate(learners):
            torch.manual_seed(1000 * t + i)  # seed i's noise stream at step t ...
            stats.append(learner.fused_step().step(batches[i]))
        for i, g in enumerate(generators):
            g.manual_seed(1000 * t + i)  # ... and the same stream for seed i in the stack
        stacked_stats = stacked.step(stack_batches(batches))
        for i, one in enumerate(stats):
            assert bool(stacked_stats[FINITE][i]) == bool(one[FINITE])
            for key in ("qf_loss", "qf_twin_loss", "policy_loss", "alpha_loss", "logps", "td_error_mean"):
                assert stacked_stats[key][i].item() == pytest.approx(
                    one[key].item(), rel=1e-5, abs=1e-6, nan_ok=True
                ), (
                    key,
                    i,
                    t,
                )
    return stacked


@pytest.mark.parametrize("critic_loss", ["huber", "mse"])
def test_a_stack_of_three_seeds_gives_each_seed_its_own_update(critic_loss):
    learners = [_learner(s, critic_loss) for s in SEEDS]
    first = [learner.module[DEFAULT_MODULE_ID].unwrapped().pi_encoder for learner in learners]
    # The seeds start apart (each module built with its own seed), so a mixed-up slice shows.
    weights = [next(enc.parameters()).detach().clone() for enc in first]
    assert not torch.equal(weights[0], weights[1]) and not torch.equal(weights[1], weights[2])
    before_target = [
        learner.module[DEFAULT_MODULE_ID].unwrapped().target_qf_encoder.net.mlp[0].weight.detach().clone()
        for learner in learners
    ]
    stacked = _run(learners, [_batch(s) for s in SEEDS], critic_loss=critic_loss)
    for i, learner in enumerate(learners):
        _assert_seed_matches(stacked, learner, i)
        after = learner.module[DEFAULT_MODULE_ID].unwrapped().target_qf_encoder.net.mlp[0].weight
        assert not torch.equal(before_target[i], after)  # the targets moved, and the stack followed
    assert stacked.skipped.tolist() == [0, 0, 0]
    assert stacked.optimizer.step_count.tolist() == [3.0, 3.0, 3.0]


def test_a_seed_with_a_non_finite_gradient_stays_put_and_the_others_step():
    learners = [_learner(s) for s in SEEDS]
    bad = _batch(1, reward=float("nan"))
    stacked, _ = _stack_of(learners)
    start = {
        name: [(w[1].clone(), b[1].clone()) for w, b in stacked.agents.nets[name]] for name, _, _ in NETWORKS
    }
    start_alpha = stacked.agents.log_alpha[1].clone()
    stacked = _run(learners, [_batch(0), bad, _batch(2)], steps=2)
    assert stacked.skipped.tolist() == [0, 2, 0]
    assert stacked.optimizer.step_count.tolist() == [2.0, 0.0, 2.0]
    for name, _, _ in NETWORKS:  # seed 1: parameters and targets untouched, and finite
        for (weight, bias), (w0, b0) in zip(stacked.agents.nets[name], start[name], strict=True):
            assert torch.equal(weight[1], w0) and torch.equal(bias[1], b0), name
    assert torch.equal(stacked.agents.log_alpha[1], start_alpha)
    for i in (0, 2):  # the others took their own one-seed steps
        _assert_seed_matches(stacked, learners[i], i)


def test_an_inactive_seed_keeps_everything_and_is_not_counted_as_skipped():
    learners = [_learner(s) for s in SEEDS]
    stacked, generators = _stack_of(learners)
    start = stacked.get_state()
    active = torch.tensor([True, False, True])
    for t in range(2):
        for i in (0, 2):
            torch.manual_seed(1000 * t + i)
            learners[i].fused_step().step(_batch(i))
        for i, g in enumerate(generators):
            g.manual_seed(1000 * t + i)
        stacked.step(stack_batches([_batch(s) for s in SEEDS]), active=active)
    now = stacked.get_state()
    for key in ("flat", "target_flat", "exp_avg", "exp_avg_sq"):
        np.testing.assert_array_equal(now[key][1], start[key][1], err_msg=key)
    assert now["step_count"].tolist() == [2.0, 0.0, 2.0] and now["skipped"].tolist() == [0, 0, 0]
    for i in (0, 2):
        _assert_seed_matches(stacked, learners[i], i)


def test_write_to_puts_each_seed_back_into_its_module():
    learners = [_learner(s) for s in SEEDS]
    stacked = _run(learners, [_batch(s) for s in SEEDS], steps=1)
    fresh = [_learner(s) for s in SEEDS]  # the untrained modules, then seed i's trained slice
    modules = [learner.module[DEFAULT_MODULE_ID].unwrapped() for learner in fresh]
    log_alphas = [learner.curr_log_alpha[DEFAULT_MODULE_ID] for learner in fresh]
    stacked.agents.write_to(modules, log_alphas)
    for i, learner in enumerate(fresh):
        _assert_seed_matches(stacked, learner, i)


def test_a_restored_stack_continues_exactly_and_a_foreign_snapshot_is_refused():
    learners = [_learner(s) for s in SEEDS]
    batch = stack_batches([_batch(s) for s in SEEDS])
    first, _ = _stack_of(learners)
    fresh, _ = _stack_of(learners)  # built before any step: the snapshot must carry everything
    for g in first.generators:
        g.manual_seed(7)
    first.step(batch)
    first.step(batch)
    snapshot = first.get_state()
    ahead = [first.step(batch)["qf_loss"].clone() for _ in range(2)]
    fresh.set_state(snapshot)
    again = [fresh.step(batch)["qf_loss"].clone() for _ in range(2)]
    for want, got in zip(ahead, again, strict=True):
        assert torch.equal(want, got)
    assert torch.equal(first.agents.flat, fresh.agents.flat)
    assert torch.equal(first.agents.target_flat, fresh.agents.target_flat)
    assert torch.equal(first.optimizer.exp_avg_sq, fresh.optimizer.exp_avg_sq)
    assert fresh.optimizer.step_count.tolist() == [4.0, 4.0, 4.0]
    two, _ = _stack_of(learners[:2])
    before = two.agents.flat.detach().clone()
    with pytest.raises(
        ValueError, match=r"flat has shape \(3, \d+\), this stack's is \(2, \d+\) \(2 seeds\)"
    ):
        two.set_state(snapshot)
    assert torch.equal(two.agents.flat, before)


def test_one_batched_forward_acts_as_each_seeds_module_acts():
    """The traversal's runner samples a seed's action from its module's distribution (exploring) or takes
    its deterministic twin; the stack's `act` gives every seed the same in one pass."""
    learners = [_learner(s) for s in SEEDS]
    stacked, _ = _stack_of(learners)
    obs = torch.as_tensor(np.random.default_rng(0).uniform(0, 1, (3, 5, 4)), dtype=torch.float32)
    generators = [torch.Generator().manual_seed(10 + i) for i in range(3)]
    noise = torch.stack([torch.empty(5, 2).normal_(generator=g) for g in generators])
    explored, greedy = stacked.agents.act(obs, noise), stacked.agents.act(obs)
    for i, learner in enumerate(learners):
        module = learner.module[DEFAULT_MODULE_ID].unwrapped()
        with torch.no_grad():
            logits = module._forward_exploration({"obs": obs[i]})["action_dist_inputs"]
            dist = module.get_exploration_action_dist_cls().from_logits(logits)
            torch.manual_seed(10 + i)  # the module's sample draws its noise as seed i's generator did
            torch.testing.assert_close(explored[i], dist.sample(), rtol=1e-5, atol=1e-6)
            torch.testing.assert_close(greedy[i], dist.to_deterministic().sample(), rtol=1e-5, atol=1e-6)
    assert not torch.allclose(explored, greedy)


def test_stacking_refuses_what_it_cannot_stack():
    learner = _learner(0)
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    with pytest.raises(ValueError, match="one log alpha per module"):
        StackedSAC.from_modules([module, module], [learner.curr_log_alpha[DEFAULT_MODULE_ID]])
    agents = StackedSAC.from_modules([module], [learner.curr_log_alpha[DEFAULT_MODULE_ID]])
    other = _learner(1).module[DEFAULT_MODULE_ID].unwrapped()
    other.pi_encoder.net.mlp[1] = torch.nn.Tanh()  # a network the batched layers do not compute
    with pytest.raises(ValueError, match=r"Linear/ReLU networks .* got layers \['linear', 'Tanh', 'linear'"):
        StackedSAC.from_modules([other], [learner.curr_log_alpha[DEFAULT_MODULE_ID]])
    with pytest.raises(ValueError, match=r"one generator per seed \(1\), got 2"):
        StackedSACStep(
            agents,
            {"qf": 1e-3, "policy": 1e-3, "alpha": 1e-3},
            -2.0,
            gamma=0.99,
            tau=0.005,
            critic_loss="huber",
            generators=[torch.Generator(), torch.Generator()],
        )


def test_the_stacked_update_benchmark_prints_a_row_per_stack_and_refuses_a_bad_size(capsys, monkeypatch):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import stacked_update

    monkeypatch.setattr(stacked_update, "CAPACITY", 1_000)
    monkeypatch.setattr(
        sys, "argv", ["stacked_update.py", "--seeds", "2", "--seconds", "0.2", "--threads", "1"]
    )
    stacked_update.main()
    lines = capsys.readouterr().out.splitlines()
    rows = {line.split("  ")[0].strip(): line for line in lines if "seed-updates/s" in line}
    assert set(rows) == {"one seed, fused", "2 stacked"}
    rate, seed_rate = (float(x) for x in rows["2 stacked"].split()[2:5:2])
    assert rate > 0 and seed_rate == pytest.approx(2 * rate, abs=0.11)  # both printed to 0.1
    monkeypatch.setattr(sys, "argv", ["stacked_update.py", "--seeds", "0"])
    with pytest.raises(SystemExit) as exit_info:
        stacked_update.main()
    assert exit_info.value.code == 2
    assert "--seeds: every N must be >= 1, got [0]" in capsys.readouterr().err
