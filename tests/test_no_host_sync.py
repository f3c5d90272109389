"""What a CUDA graph captures must not talk to the host: the SAC step (one seed, as the learner runs it
with its replay sampled inside; and a stack of seeds with an `active` mask) runs under a torch dispatch
mode that raises on every host read (`_local_scalar_dense`: `.item()`, `float()`, `bool()`; `nonzero`;
`is_nonzero`) and on host data entering the step (`lift_fresh`: `torch.tensor(...)`,
`torch.as_tensor(numpy)`). The guard itself is shown to catch each of them, the per-step
`torch.tensor(...)` of the stack's former eager update among them."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from torch.utils._python_dispatch import TorchDispatchMode

from copilot_ray.algorithms.gc_sac import FlatTransitionBuffer, use_fast_learner
from copilot_ray.algorithms.gc_sac.sac_step import SACStep

SEEDS = (0, 1, 2)

HOST_OPS = {
    torch.ops.aten._local_scalar_dense.default,
    torch.ops.aten.nonzero.default,
    torch.ops.aten.is_nonzero.default,
    torch.ops.aten.lift_fresh.default,
}


def _learner(seed=0):
    cfg = SACConfig().environment(
        observation_space=gym.spaces.Box(0.0, 1.0, (4,), np.float32),
        action_space=gym.spaces.Box(-1.0, 1.0, (2,), np.float32),
    )
    return (
        use_fast_learner(cfg.debugging(seed=seed), hidden=(32, 32), torch_threads=1)
        .build_learner_group()
        ._learner
    )


def _columns(n, seeds=()):
    rng = np.random.default_rng(0)
    shape = (*seeds, n)
    obs = rng.uniform(0, 1, (*shape, 4)).astype(np.float32)
    return {
        "obs": obs,
        "new_obs": np.clip(obs + rng.normal(0, 0.02, obs.shape), 0, 1).astype(np.float32),
        "actions": rng.uniform(-1, 1, (*shape, 2)).astype(np.float32),
        "rewards": np.full(shape, -1.0, np.float32),
        "terminateds": rng.random(shape) < 0.2,
    }


class HostSync(RuntimeError):
    pass


class NoHostSync(TorchDispatchMode):
    """Raises `HostSync` naming the first host-reading or host-data op; counts the ops it let pass."""

    def __init__(self):
        super().__init__()
        self.ops = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func in HOST_OPS or func.overloadpacket in {op.overloadpacket for op in HOST_OPS}:
            raise HostSync(f"host synchronisation inside the step: {func}")
        self.ops += 1
        return func(*args, **(kwargs or {}))


def test_the_learners_one_seed_update_never_syncs_with_the_host():
    learner = _learner()
    replay = FlatTransitionBuffer(100, device=learner.device)
    replay.add(_columns(40))
    run = learner._replay_run(DEFAULT_MODULE_ID, replay, 16)  # what the learner captures on a GPU
    before = learner.fused_step().flat.clone()
    guard = NoHostSync()
    with guard:
        for _ in range(3):
            stats = run()
    assert guard.ops > 100  # the step ran under the guard
    assert bool(stats["finite"][0]) and not torch.equal(before, learner.fused_step().flat)


def test_a_stack_of_seeds_with_an_active_mask_never_syncs_with_the_host():
    learners = [_learner(s) for s in SEEDS]
    step = SACStep(
        [learner.module[DEFAULT_MODULE_ID].unwrapped() for learner in learners],
        [learner.curr_log_alpha[DEFAULT_MODULE_ID] for learner in learners],
        [learner._sac_optimizers(DEFAULT_MODULE_ID) for learner in learners],
        -2.0,
        gamma=0.99,
        tau=0.005,
        critic_loss="huber",
        seeds=SEEDS,
    )
    batch = {k: torch.as_tensor(v) for k, v in _columns(32, seeds=(len(SEEDS),)).items()}
    active = torch.tensor([True, False, True])  # made before: a mask the caller keeps on the device
    guard = NoHostSync()
    with guard:
        for _ in range(2):
            step.step(batch, active=active)
    assert guard.ops > 100
    assert step.step_counts[:, 0].tolist() == [2.0, 0.0, 2.0]


@pytest.mark.parametrize(
    "host_sync",
    [
        lambda x: torch.tensor([True, False, True]),  # the former stacked update's per-step active mask
        lambda x: torch.as_tensor(np.zeros(3)),
        lambda x: x.sum().item(),
        lambda x: float(x.sum()),
        lambda x: bool(x.sum() > 0),
        lambda x: x.nonzero(),
    ],
)
def test_the_guard_catches_every_kind_of_host_sync(host_sync):
    x = torch.randn(5)
    with pytest.raises(HostSync), NoHostSync():
        host_sync(x)
