"""Seeds stacked in one update (`sac_step.SACStep` over N seeds) against each seed's own step (N = 1).

A stack of seeds {0, 1, 2} must give every seed the update its one-seed step gives it for the same
batch: losses, new parameters, target critics, log alpha and Adam state, over several steps (Adam's
moments and the targets carry over). Both draw seed i's noise from seed i's Philox stream, so nothing
is handed over: a seed's stream does not depend on the stack. A seed whose gradient is not finite, or
that sits a step out, must stay where it was while the others step. All on the CPU.
"""

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray.algorithms.gc_sac import use_fast_learner
from copilot_ray.algorithms.gc_sac.sac_step import FINITE, SACStep, stack_batches, with_seed_axis

OBS_SPACE = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
ACT_SPACE = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
SEEDS = (0, 1, 2)
STATS = ("qf_loss", "qf_twin_loss", "policy_loss", "alpha_loss", "logps", "td_error_mean")


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
    """One `SACStep` over the learners' modules: their parameters and Adam state become its rows."""
    config = learners[0].config.get_config_for_module(DEFAULT_MODULE_ID)
    return SACStep(
        [learner.module[DEFAULT_MODULE_ID].unwrapped() for learner in learners],
        [learner.curr_log_alpha[DEFAULT_MODULE_ID] for learner in learners],
        [learner._sac_optimizers(DEFAULT_MODULE_ID) for learner in learners],
        learners[0].target_entropy[DEFAULT_MODULE_ID],
        gamma=config.gamma,
        tau=config.tau,
        critic_loss=critic_loss,
        seeds=[int(learner.config.seed) for learner in learners],
    )


def _state(learner):
    """A learner's module (online and target nets), log alpha and Adam moments and counts."""
    out = {k: v.detach().clone() for k, v in learner.module[DEFAULT_MODULE_ID].state_dict().items()}
    out["log_alpha"] = learner.curr_log_alpha[DEFAULT_MODULE_ID].detach().clone()
    for name, optimizer in learner.get_optimizers_for_module(DEFAULT_MODULE_ID):
        for k, state in enumerate(optimizer.state.values()):
            out.update({f"{name}/{k}/{key}": v.detach().clone() for key, v in state.items()})
    return out


def _assert_seed_matches(stacked_learner, alone_learner, i):
    want, got = _state(alone_learner), _state(stacked_learner)
    assert want.keys() == got.keys()
    for key in want:
        torch.testing.assert_close(
            got[key], want[key], rtol=1e-5, atol=1e-6, msg=lambda m, k=key: f"seed {i} {k}: {m}"
        )


def _run(batches, steps=3, critic_loss="huber", active=None):
    """`steps` stacked steps for seeds SEEDS and each seed's own one-seed steps (where active);
    (stacked learners, the step, alone learners)."""
    stacked_learners = [_learner(s, critic_loss) for s in SEEDS]
    alone = [_learner(s, critic_loss) for s in SEEDS]
    step = _stack_of(stacked_learners, critic_loss)
    mask = None if active is None else torch.tensor(active)
    for t in range(steps):
        stacked_stats = step.step(stack_batches(batches), active=mask)
        for i, learner in enumerate(alone):
            if active is not None and not active[i]:
                continue
            one = learner.fused_step().step(with_seed_axis(batches[i]))
            assert bool(stacked_stats[FINITE][i]) == bool(one[FINITE][0])
            for key in STATS:
                assert stacked_stats[key][i].item() == pytest.approx(
                    one[key][0].item(), rel=1e-5, abs=1e-6, nan_ok=True
                ), (key, i, t)
    return stacked_learners, step, alone


@pytest.mark.parametrize("critic_loss", ["huber", "mse"])
def test_a_stack_of_three_seeds_gives_each_seed_its_own_update(critic_loss):
    fresh = [_learner(s) for s in SEEDS]
    weights = [next(f.module[DEFAULT_MODULE_ID].pi_encoder.parameters()).detach() for f in fresh]
    # The seeds start apart (each module built with its own seed), so a mixed-up row shows.
    assert not torch.equal(weights[0], weights[1]) and not torch.equal(weights[1], weights[2])
    stacked, step, alone = _run([_batch(s) for s in SEEDS], critic_loss=critic_loss)
    for i in range(len(SEEDS)):
        _assert_seed_matches(stacked[i], alone[i], i)
        before = _state(fresh[i])["target_qf_encoder.net.mlp.0.weight"]
        assert not torch.equal(before, _state(stacked[i])["target_qf_encoder.net.mlp.0.weight"])
    assert step.skipped.tolist() == [0, 0, 0]
    assert step.step_counts[:, 0].tolist() == [3.0, 3.0, 3.0]
    # Seed i's noise stream is where seed i's own one-seed stream is.
    assert step.noise.counters.tolist() == [int(a.fused_step().noise.counters[0]) for a in alone]


def test_a_seed_with_a_non_finite_gradient_stays_put_and_the_others_step():
    start = _state(_learner(1))
    stacked, step, alone = _run([_batch(0), _batch(1, reward=float("nan")), _batch(2)], steps=2)
    assert step.skipped.tolist() == [0, 2, 0]
    assert step.step_counts[:, 0].tolist() == [2.0, 0.0, 2.0]
    after = _state(stacked[1])
    for key, value in start.items():  # seed 1: parameters, targets, log alpha, Adam state untouched
        if key in after:
            assert torch.equal(after[key], value), key
    assert all(torch.isfinite(v).all() for v in after.values())
    for i in (0, 2):  # the others took their own one-seed steps
        _assert_seed_matches(stacked[i], alone[i], i)


def test_a_seed_that_sits_steps_out_keeps_everything_then_steps_as_it_would_alone():
    batches = [_batch(s) for s in SEEDS]
    stacked, step, alone = _run(batches, steps=2, active=[True, False, True])
    assert step.skipped.tolist() == [0, 0, 0] and step.step_counts[:, 0].tolist() == [2.0, 0.0, 2.0]
    assert step.noise.counters[1].item() == 0  # its stream did not move
    untrained = _learner(1)
    untrained.fused_step()  # its Adam state made (zeros, no steps), as the stack's is
    _assert_seed_matches(stacked[1], untrained, 1)  # still where it started
    # Its first step, two stacked steps late, is its first step alone: its stream waited for it.
    stats = step.step(stack_batches(batches), active=torch.tensor([False, True, False]))
    one = alone[1].fused_step().step(with_seed_axis(batches[1]))
    assert stats["qf_loss"][1].item() == pytest.approx(one["qf_loss"][0].item(), rel=1e-5, abs=1e-6)
    for i in SEEDS:
        _assert_seed_matches(stacked[i], alone[i], i)


def test_a_restored_stack_continues_exactly_and_a_foreign_snapshot_is_refused():
    batch = stack_batches([_batch(s) for s in SEEDS])
    first = _stack_of([_learner(s) for s in SEEDS])
    fresh = _stack_of([_learner(s) for s in SEEDS])  # built before any step: the snapshot carries it all
    first.step(batch)
    first.step(batch)
    snapshot = first.get_state()
    ahead = [first.step(batch)["qf_loss"].clone() for _ in range(2)]
    fresh.set_state(snapshot)
    again = [fresh.step(batch)["qf_loss"].clone() for _ in range(2)]
    for want, got in zip(ahead, again, strict=True):
        assert torch.equal(want, got)
    for key in ("flat", "target_flat", "exp_avg_sq", "step_counts"):
        assert torch.equal(getattr(first, key), getattr(fresh, key)), key
    assert fresh.step_counts[:, 0].tolist() == [4.0, 4.0, 4.0]
    two = _stack_of([_learner(s) for s in SEEDS[:2]])
    before = two.flat.clone()
    with pytest.raises(ValueError, match=r"flat has shape \(3, \d+\), this step's is \(2, \d+\) \(2 seeds\)"):
        two.set_state(snapshot)
    assert torch.equal(two.flat, before)


def test_one_batched_forward_acts_as_each_seeds_module_acts():
    """The traversal's runner samples a seed's action from its module's distribution (exploring) or takes
    its deterministic twin; the stack's `act` gives every seed the same in one pass."""
    learners = [_learner(s) for s in SEEDS]
    step = _stack_of(learners)
    obs = torch.as_tensor(np.random.default_rng(0).uniform(0, 1, (3, 5, 4)), dtype=torch.float32)
    noise = torch.as_tensor(np.random.default_rng(1).normal(0, 1, (3, 5, 2)), dtype=torch.float32)
    explored, greedy = step.act(obs, noise), step.act(obs)
    for i, learner in enumerate(learners):
        module = learner.module[DEFAULT_MODULE_ID].unwrapped()
        with torch.no_grad():
            logits = module._forward_exploration({"obs": obs[i]})["action_dist_inputs"]
            dist = module.get_exploration_action_dist_cls().from_logits(logits)
            loc, scale = dist._dist.loc, dist._dist.scale
            torch.testing.assert_close(
                explored[i], dist._squash(loc + noise[i] * scale), rtol=1e-5, atol=1e-6
            )
            torch.testing.assert_close(greedy[i], dist.to_deterministic().sample(), rtol=1e-5, atol=1e-6)
    assert not torch.allclose(explored, greedy)
    one = _stack_of([_learner(2)])  # N = 1 (no vmap) acts as seed 2 of the stack
    torch.testing.assert_close(one.act(obs[2:], noise[2:]), explored[2:], rtol=1e-5, atol=1e-6)


def test_the_traced_act_acts_with_the_weights_of_the_moment_as_the_vmapped_actor_does():
    """For N > 1 `act` replays a graph traced once per input shape: it must read the actor's current
    parameters (an update moves its actions), give what the vmapped actor gives to the bit, and trace
    again only for a new shape or the other kind of action."""
    learners = [_learner(s) for s in SEEDS]
    step = _stack_of(learners)
    obs = torch.as_tensor(np.random.default_rng(0).uniform(0, 1, (3, 1, 4)), dtype=torch.float32)
    noise = torch.as_tensor(np.random.default_rng(1).normal(0, 1, (3, 1, 2)), dtype=torch.float32)
    before = step.act(obs, noise)
    for _ in range(3):
        step.step(stack_batches([_batch(s) for s in SEEDS]))
    after = step.act(obs, noise)
    assert not torch.allclose(before, after)
    actor = step.leaves[len(step.critic_layout) : len(step.critic_layout) + len(step.actor_layout)]
    with torch.no_grad():
        vmapped = torch.vmap(lambda p, o, z: step._act_one_seed(p, o, z))(actor, obs, noise)
    assert torch.equal(after, vmapped)
    step.act(obs, noise), step.act(obs), step.act(obs.repeat(1, 2, 1), noise.repeat(1, 2, 1))
    assert len(step._traced_acts) == 3


def test_the_step_refuses_what_it_cannot_stack():
    learner = _learner(0)
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    log_alpha = learner.curr_log_alpha[DEFAULT_MODULE_ID]
    common = {"gamma": 0.99, "tau": 0.005, "critic_loss": "huber"}
    with pytest.raises(ValueError, match="one log alpha and one seed per module"):
        SACStep(
            [module, module],
            [log_alpha],
            None,
            -2.0,
            seeds=[0, 1],
            lrs={"qf": 1, "policy": 1, "alpha": 1},
            **common,
        )
    with pytest.raises(ValueError, match="need the optimizers or the learning rates"):
        SACStep([module], [log_alpha], None, -2.0, seeds=[0], **common)
    module.twin_q = False
    with pytest.raises(ValueError, match=r"twin critics \(twin_q=True\)"):
        SACStep(
            [module], [log_alpha], None, -2.0, seeds=[0], lrs={"qf": 1, "policy": 1, "alpha": 1}, **common
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


def test_a_batch_without_the_seed_axis_is_refused_naming_the_shape():
    step = _stack_of([_learner(s) for s in SEEDS[:2]])
    with pytest.raises(
        ValueError, match=r"\[N, B, ...\] columns for its 2 seed\(s\); got actions of shape \(64, 2\)"
    ):
        step.step(_batch(0))
    with pytest.raises(ValueError, match=r"got actions of shape \(1, 64, 2\)"):
        step.step(with_seed_axis(_batch(0)))
