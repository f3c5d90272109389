"""One SAC gradient step as one function over device tensors, with no host synchronisation inside.

`FusedSACStep.step(batch)` does what `GCSACTorchLearner`'s RLlib path does per minibatch (the
module's training forward pass, `losses.sac_losses`, one backward pass, the finite check, the three
Adam steps, the Polyak update of the target critics), with one difference: the finite check never
reaches the host. It is a device flag that

* is handed to the fused Adam kernels as `found_inf` (the flag PyTorch's AMP grad scaler uses to skip
  a step on the device): a step with a non-finite gradient leaves the parameters, `exp_avg`,
  `exp_avg_sq` and the step counts of all three optimizers untouched (log alpha is the temperature
  optimizer's parameter);
* weights the Polyak update (`tau` when finite, 0 when not: `lerp` with weight 0 is exact);
* adds one to `skipped`, a device counter the learner reads once per call.

So a bad step is a no-op and a good one is the step RLlib's path takes, with the same kernels. With
no `.item()` inside, the step can be captured in one CUDA graph (`graph_capture.py`) and replayed,
or compiled. `sampled_step(replay, batch_size)` puts the replay's sampling inside it too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import torch

from copilot_ray.algorithms.gc_sac.losses import sac_losses

TOTAL_LOSS = "total_loss"
FINITE = "finite"


class FusedSACStep:
    """The SAC step of one module (module docstring).

    Args:
        module: the `GCSACTorchRLModule` (continuous actions, target critics made).
        log_alpha: log(alpha), the temperature optimizer's parameter.
        optimizers: the module's Adam optimizers (critics, actor, temperature), each `fused=True`:
            only the fused kernels take a device-side skip flag.
        target_entropy: SAC's entropy target.
        gamma, tau: discount and Polyak rate.
        critic_loss: "huber" or "mse".
        twin_q: whether the module has a twin critic.
    """

    def __init__(
        self,
        module: torch.nn.Module,
        log_alpha: torch.Tensor,
        optimizers: Sequence[torch.optim.Optimizer],
        target_entropy: torch.Tensor | float,
        *,
        gamma: float,
        tau: float,
        critic_loss: str,
        twin_q: bool,
    ):
        not_fused = [type(o).__name__ for o in optimizers if not all(g.get("fused") for g in o.param_groups)]
        if not_fused:
            raise ValueError(
                f"FusedSACStep needs fused optimizers (their found_inf skips a step on the device); "
                f"got {not_fused} with fused=False"
            )
        self.module = module
        self.log_alpha = log_alpha
        self.optimizers = list(optimizers)
        self.target_entropy = target_entropy
        self.gamma, self.tau = float(gamma), float(tau)
        self.critic_loss, self.twin_q = critic_loss, bool(twin_q)
        self.params = [p for o in self.optimizers for g in o.param_groups for p in g["params"]]
        device = log_alpha.device
        main, target = [], []
        for main_net, target_net in module.get_target_network_pairs():
            main += [p.data for p in main_net.parameters()]
            target += [p.data for p in target_net.parameters()]
        self._main, self._target = main, target
        # Device-resident flags and counter: written in place, so a captured graph keeps them.
        self.found_inf = torch.zeros((), dtype=torch.float32, device=device)
        self._polyak_weight = torch.zeros((), dtype=torch.float32, device=device)
        self.skipped = torch.zeros((), dtype=torch.int64, device=device)

    def step(self, batch: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """One gradient step on `batch` (device tensors: obs, new_obs, actions, rewards, terminateds).
        Returns the loss statistics, `total_loss` and `finite` (a 0-d bool) as device tensors."""
        for opt in self.optimizers:
            opt.zero_grad(set_to_none=True)
        fwd_out = self.module.forward_train(dict(batch))
        total, stats = sac_losses(
            fwd_out,
            batch,
            self.log_alpha,
            self.target_entropy,
            gamma=self.gamma,
            critic_loss=self.critic_loss,
            twin_q=self.twin_q,
        )
        total.backward()
        grads = [p.grad for p in self.params if p.grad is not None]
        finite = torch.isfinite(torch.stack(torch._foreach_norm(grads))).all()
        with torch.no_grad():
            self.found_inf.copy_(torch.logical_not(finite))
            for opt in self.optimizers:
                # Read by Adam.step (fused); removed after, so RLlib's own path never sees a stale flag.
                opt.found_inf = self.found_inf
                try:
                    opt.step()
                finally:
                    del opt.found_inf
            self._polyak_weight.copy_(finite * self.tau)
            torch._foreach_lerp_(self._target, self._main, [self._polyak_weight] * len(self._target))
            self.skipped.add_(torch.logical_not(finite))
        stats[TOTAL_LOSS] = total.detach()
        stats[FINITE] = finite
        return stats

    def sampled_step(self, replay: Any, batch_size: int) -> Callable[[], dict[str, torch.Tensor]]:
        """A zero-argument step that samples `batch_size` transitions from `replay` (a device buffer:
        `sample(batch_size)` -> device tensors, no host sync) and trains on them."""

        def run() -> dict[str, torch.Tensor]:
            return self.step(replay.sample(batch_size))

        return run
