"""N seeds' SAC agents as one: stacked networks and one update for all of them (a trial's seed axis).

Seeds of one configuration run the same networks on the same shapes, so their actors and critics are
kept as stacked tensors (a layer's weight [N, out, in], its bias [N, out]) and evaluated as batched
matrix products (`torch.baddbmm`): one kernel per layer serves every seed, which is what makes a GPU
pay (one captured graph per update for N seeds instead of N).

`StackedSACStep.step(batch)` is N `fused_step.FusedSACStep.step`s at once, seed i reading row i of
every batch column ([N, B, ...]):

* the losses are `losses.sac_losses` itself, vmapped over the seed axis: each seed averages over its
  own batch, and the sum over seeds back-propagates each seed's gradient into its own slice;
* each seed has its own Adam moments, step count and temperature (`StackedAdam`);
* the finite check is per seed: a seed with a non-finite gradient keeps its parameters, moments, step
  count and target critics, and its own entry of `skipped` goes up; the other seeds step;
* noise: with `generators` (one `torch.Generator` per seed), seed i draws its reparameterisation noise
  from its own generator in the order its one-seed step draws it from torch's default generator, so
  seed i's update equals its one-seed update for the same generator state (tested on the CPU);
  without, one draw for all seeds comes from the default generator (what a CUDA graph captures).

`StackedSACStep.get_state()` / `set_state()` checkpoint every seed (parameters, targets, Adam moments and
counts, skips, noise streams); a restore writes in place, so a captured graph stays valid.

`StackedSAC.from_modules(modules)` stacks N `catalog.GCSACTorchRLModule`s (each built with its seed, so
seed i starts where its one-seed run starts); `write_to(modules)` copies seed i back into module i
(weight sync to env runners, checkpoints in the one-seed format).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.sac.sac_learner import QF_PREDS, QF_TWIN_PREDS
from ray.rllib.core.columns import Columns
from ray.rllib.utils.numpy import MAX_LOG_NN_OUTPUT, MIN_LOG_NN_OUTPUT

from copilot_ray.algorithms.gc_sac.fused_step import FINITE, TOTAL_LOSS
from copilot_ray.algorithms.gc_sac.losses import sac_losses

# The networks of a `GCSACTorchRLModule`, each an encoder followed by a head: (name, encoder, head).
NETWORKS = (
    ("pi", "pi_encoder", "pi"),
    ("qf", "qf_encoder", "qf"),
    ("qf_twin", "qf_twin_encoder", "qf_twin"),
    ("target_qf", "target_qf_encoder", "target_qf"),
    ("target_qf_twin", "target_qf_twin_encoder", "target_qf_twin"),
)
CRITICS = ("qf", "qf_twin")
LOSS_COLUMNS = (Columns.REWARDS, Columns.TERMINATEDS, "weights", "n_step")
Layers = list[tuple[torch.Tensor, torch.Tensor]]


def _linear_layers(encoder: torch.nn.Module, head: torch.nn.Module) -> list[torch.nn.Linear]:
    """The Linear layers of encoder + head, checked to be Linear, ReLU, ..., Linear (SB3's shape)."""
    leaves = [m for net in (encoder, head) for m in net.modules() if not list(m.children())]
    leaves = [m for m in leaves if not isinstance(m, torch.nn.Identity)]
    names = {torch.nn.Linear: "linear", torch.nn.ReLU: "relu"}
    kinds = [names.get(type(m), type(m).__name__) for m in leaves]
    want = ["linear", "relu"] * (len(kinds) // 2) + ["linear"]
    if kinds != want:
        raise ValueError(
            f"seed stacking needs Linear/ReLU networks with a linear head (fcnet_activation='relu', "
            f"head_fcnet_hiddens=[]); got layers {kinds}"
        )
    return [m for m in leaves if isinstance(m, torch.nn.Linear)]


def _mlp(layers: Layers, x: torch.Tensor, detach: bool = False) -> torch.Tensor:
    """x [N, B, in] through stacked layers: ReLU after every layer but the last."""
    last = len(layers) - 1
    for i, (weight, bias) in enumerate(layers):
        if detach:
            weight, bias = weight.detach(), bias.detach()
        x = torch.baddbmm(bias.unsqueeze(1), x, weight.transpose(1, 2))
        if i < last:
            x = torch.relu(x)
    return x


class StackedSAC:
    """N seeds' actor, twin critics, target critics and temperatures as stacked tensors.

    Every trained number of a seed lives in one row of one flat leaf tensor `flat` [N, P] (the
    critics, then the actor, then log alpha), and the target critics in `target_flat` [N, P_critics]
    with the critics' layout; a layer's weight and bias are views into a row. So the optimizer, the
    finite check and the Polyak update are a few operations on two tensors, whatever the depth of the
    networks, and one gradient tensor holds every seed's gradient."""

    def __init__(
        self,
        flat: torch.Tensor,
        target_flat: torch.Tensor,
        shapes: dict[str, list],
        action_bounds=(-1.0, 1.0),
    ):
        self.flat = flat
        self.target_flat = target_flat
        self.shapes = shapes  # net -> [(weight shape, bias shape)] per layer, in layout order
        self.low, self.high = (float(b) for b in action_bounds)
        self.num_seeds = int(flat.shape[0])
        offsets, at = {}, 0
        for name in (*CRITICS, "pi"):
            offsets[name] = []
            for w_shape, b_shape in shapes[name]:
                w_size, b_size = math.prod(w_shape), math.prod(b_shape)
                offsets[name].append((at, at + w_size, at + w_size + b_size))
                at += w_size + b_size
            if name == CRITICS[-1]:
                self.num_critic_params = at
        self._offsets = offsets
        self.segments = {  # where each optimizer group's parameters are in a row
            "qf": (0, self.num_critic_params),
            "policy": (self.num_critic_params, at),
            "alpha": (at, at + 1),
        }

    @classmethod
    def from_modules(
        cls, modules: Sequence[torch.nn.Module], log_alphas: Sequence[torch.Tensor]
    ) -> StackedSAC:
        """Stacks N modules (same shapes; twin critics required) and their log alphas ([1] each)."""
        if not modules or len(modules) != len(log_alphas):
            raise ValueError(f"need one log alpha per module, got {len(modules)} modules, {len(log_alphas)}")
        if not all(getattr(m, "twin_q", False) for m in modules):
            raise ValueError("seed stacking needs twin critics (twin_q=True)")
        layers = {
            name: [_linear_layers(getattr(m, enc), getattr(m, head)) for m in modules]
            for name, enc, head in NETWORKS
        }
        shapes = {
            name: [(tuple(lin.weight.shape), tuple(lin.bias.shape)) for lin in per_seed[0]]
            for name, per_seed in layers.items()
        }

        def rows(names, with_alpha=False):
            out = []
            for i in range(len(modules)):
                parts = [
                    t.detach().reshape(-1)
                    for name in names
                    for lin in layers[name][i]
                    for t in (lin.weight, lin.bias)
                ]
                if with_alpha:
                    parts.append(log_alphas[i].detach().reshape(1))
                out.append(torch.cat(parts))
            return torch.stack(out)

        flat = rows((*CRITICS, "pi"), with_alpha=True).requires_grad_(True)
        target_flat = rows(tuple("target_" + c for c in CRITICS))
        return cls(flat, target_flat, shapes)

    def _views(self, source: torch.Tensor, name: str) -> Layers:
        n = self.num_seeds
        return [
            (source[:, a:b].view(n, *w_shape), source[:, b:c].view(n, *b_shape))
            for (a, b, c), (w_shape, b_shape) in zip(self._offsets[name], self.shapes[name], strict=True)
        ]

    @property
    def nets(self) -> dict[str, Layers]:
        """Every network's layers as (weight [N, out, in], bias [N, out]) views into the flat rows."""
        out = {name: self._views(self.flat, name) for name in (*CRITICS, "pi")}
        for c in CRITICS:
            out["target_" + c] = self._views(self.target_flat, c)
        return out

    @property
    def log_alpha(self) -> torch.Tensor:
        """[N, 1] view of each seed's log alpha."""
        return self.flat[:, -1:]

    def write_to(self, modules: Sequence[torch.nn.Module], log_alphas: Sequence[torch.Tensor] = ()) -> None:
        """Copies seed i's networks (and log alpha) into modules[i] (and log_alphas[i])."""
        nets = self.nets
        with torch.no_grad():
            for i, module in enumerate(modules):
                for name, encoder, head in NETWORKS:
                    for layer, (weight, bias) in zip(
                        _linear_layers(getattr(module, encoder), getattr(module, head)),
                        nets[name],
                        strict=True,
                    ):
                        layer.weight.copy_(weight[i])
                        layer.bias.copy_(bias[i])
            for i, log_alpha in enumerate(log_alphas):
                log_alpha.copy_(self.log_alpha[i].reshape(log_alpha.shape))

    # ------------------------------------------------------------------ forward passes
    def q(
        self,
        nets: dict[str, Layers],
        obs: torch.Tensor,
        actions: torch.Tensor,
        prefix: str = "",
        detach: bool = False,
    ):
        """(Q1, Q2) [N, B] of the online (prefix "") or target ("target_") critics."""
        x = torch.cat([obs, actions], dim=-1)
        return tuple(_mlp(nets[prefix + c], x, detach).squeeze(-1) for c in CRITICS)

    def policy(
        self, nets: dict[str, Layers], obs: torch.Tensor, noise: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(squashed action, its log-probability) for standard-normal `noise` [N, B, A]: RLlib's
        `TorchSquashedGaussian.from_logits(...).rsample_and_logp()` with the noise given."""
        loc, log_std = _mlp(nets["pi"], obs).chunk(2, dim=-1)
        scale = torch.clamp(log_std, MIN_LOG_NN_OUTPUT, MAX_LOG_NN_OUTPUT).exp()
        unsquashed = loc + noise * scale
        logp = torch.distributions.Normal(loc, scale, validate_args=False).log_prob(unsquashed).sum(-1)
        jacobian = 2.0 * (math.log(2.0) - unsquashed - torch.nn.functional.softplus(-2.0 * unsquashed))
        action = ((torch.tanh(unsquashed) + 1.0) / 2.0) * (self.high - self.low) + self.low
        return torch.clamp(action, self.low, self.high), logp - jacobian.sum(-1)

    @torch.no_grad()
    def act(self, obs: torch.Tensor, noise: torch.Tensor | None = None) -> torch.Tensor:
        """Every seed's actions for its own observations `obs` [N, E, d] in one batched forward pass,
        as the traversal's env runner takes them from a seed's module: with standard-normal `noise`
        [N, E, A] a sample of the squashed Gaussian (exploring), without it the distribution's
        deterministic twin (RLlib's: the Gaussian's mean, before squashing)."""
        if noise is None:
            return _mlp(self.nets["pi"], obs).chunk(2, dim=-1)[0]
        return self.policy(self.nets, obs, noise)[0]

    def forward_train(self, batch: Mapping[str, torch.Tensor], noise: torch.Tensor, noise_next: torch.Tensor):
        """`GCSACTorchRLModule._forward_train_continuous`'s outputs, each with a leading seed axis."""
        obs, next_obs = batch[Columns.OBS], batch[Columns.NEXT_OBS]
        nets = self.nets
        out = {}
        out[QF_PREDS], out[QF_TWIN_PREDS] = self.q(nets, obs, batch[Columns.ACTIONS])
        actions_new, out["logp_resampled"] = self.policy(nets, obs, noise)
        out["q_curr"] = torch.min(*self.q(nets, obs, actions_new, detach=True))  # gradients to the actor only
        with torch.no_grad():
            actions_next, out["logp_next_resampled"] = self.policy(nets, next_obs, noise_next)
            out["q_target_next"] = torch.min(*self.q(nets, next_obs, actions_next, prefix="target_"))
        return out


class StackedAdam:
    """Adam on the rows of one [N, P] tensor, a row per seed: per-seed step counts and skips.

    torch's Adam steps every element of a tensor with one step count and skips a step for all or
    none; here row i follows torch's Adam (eps, betas, bias correction) with its own count and its
    segment's learning rate, and a seed whose `ok` entry is False keeps its row, moments and count."""

    def __init__(self, flat: torch.Tensor, lrs: torch.Tensor, betas=(0.9, 0.999), eps: float = 1e-7):
        self.flat = flat
        self.lrs = lrs  # [P]: each parameter's learning rate
        self.beta1, self.beta2 = betas
        self.eps = float(eps)
        self.step_count = torch.zeros(flat.shape[0], device=flat.device)
        self.exp_avg = torch.zeros_like(flat, requires_grad=False)
        self.exp_avg_sq = torch.zeros_like(flat, requires_grad=False)

    @torch.no_grad()
    def step(self, ok: torch.Tensor) -> None:
        """One Adam step for the rows where `ok` [N] (bool) is True."""
        count = self.step_count + ok
        keep = ok.unsqueeze(1)
        grad = torch.where(keep, self.flat.grad, 0.0)  # a skipped seed's NaN must not reach its moments
        self.exp_avg.lerp_(grad, keep * (1.0 - self.beta1))
        self.exp_avg_sq.lerp_(grad * grad, keep * (1.0 - self.beta2))
        # A row that has never stepped has no bias correction (0 / 0): its coefficient is 0, not NaN.
        bias1 = torch.where(count > 0, 1.0 - self.beta1**count, 1.0)
        bias2 = torch.where(count > 0, 1.0 - self.beta2**count, 1.0)
        denom = self.exp_avg_sq.sqrt() / bias2.sqrt().unsqueeze(1) + self.eps
        coef = torch.where(ok, 1.0 / bias1, 0.0).unsqueeze(1) * self.lrs
        self.flat.sub_(coef * self.exp_avg / denom)
        self.step_count.copy_(count)


class StackedSACStep:
    """N seeds' SAC step (module docstring).

    Args:
        agents: the stacked networks and temperatures.
        lrs: {"qf", "policy", "alpha"} learning rates (one configuration: the same for every seed).
        target_entropy, gamma, tau, critic_loss: as `FusedSACStep`'s.
        generators: one per seed, for per-seed noise streams (else torch's default generator).
    """

    def __init__(
        self,
        agents: StackedSAC,
        lrs: Mapping[str, float],
        target_entropy: torch.Tensor | float,
        *,
        gamma: float,
        tau: float,
        critic_loss: str,
        generators: Sequence[torch.Generator] | None = None,
    ):
        if generators is not None and len(generators) != agents.num_seeds:
            raise ValueError(f"need one generator per seed ({agents.num_seeds}), got {len(generators)}")
        device = agents.flat.device
        wrong = sorted({str(g.device) for g in generators or [] if g.device.type != device.type})
        if wrong:
            raise ValueError(f"the seeds' generators must be on the stack's device ({device}), got {wrong}")
        self.agents = agents
        self.generators = None if generators is None else list(generators)
        self.target_entropy = target_entropy
        self.gamma, self.tau, self.critic_loss = float(gamma), float(tau), critic_loss
        lr_of = torch.empty(agents.flat.shape[1], device=agents.flat.device)
        for group, (start, end) in agents.segments.items():
            lr_of[start:end] = float(lrs[group])
        self.optimizer = StackedAdam(agents.flat, lr_of)
        self.skipped = torch.zeros(agents.num_seeds, dtype=torch.int64, device=agents.flat.device)

    # ------------------------------------------------------------------ checkpoints
    def get_state(self) -> dict[str, Any]:
        """Every seed's parameters, targets, Adam moments and counts, skip counts and noise streams
        (numpy / bytes, device-free)."""
        opt = self.optimizer
        tensors = {
            "flat": self.agents.flat,
            "target_flat": self.agents.target_flat,
            "exp_avg": opt.exp_avg,
            "exp_avg_sq": opt.exp_avg_sq,
            "step_count": opt.step_count,
            "skipped": self.skipped,
        }
        state: dict[str, Any] = {k: v.detach().cpu().numpy().copy() for k, v in tensors.items()}
        state["generators"] = None if self.generators is None else [g.get_state() for g in self.generators]
        return state

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores `get_state`'s snapshot in place (the tensors keep their storage, so a captured graph
        stays valid). A snapshot of another stack shape is refused before anything changes."""
        targets = {
            "flat": self.agents.flat,
            "target_flat": self.agents.target_flat,
            "exp_avg": self.optimizer.exp_avg,
            "exp_avg_sq": self.optimizer.exp_avg_sq,
            "step_count": self.optimizer.step_count,
            "skipped": self.skipped,
        }
        for key, tensor in targets.items():
            shape = tuple(np.shape(state[key]))
            if shape != tuple(tensor.shape):
                raise ValueError(
                    f"stacked SAC state: {key} has shape {shape}, this stack's is {tuple(tensor.shape)} "
                    f"({self.agents.num_seeds} seeds)"
                )
        if (state.get("generators") is None) != (self.generators is None):
            raise ValueError(
                "stacked SAC state: per-seed generators in one of the snapshot and this stack only"
            )
        with torch.no_grad():
            for key, tensor in targets.items():
                tensor.copy_(torch.as_tensor(state[key]))
        for g, g_state in zip(self.generators or [], state.get("generators") or [], strict=True):
            g.set_state(g_state)

    def _noise(
        self, like: torch.Tensor, drawing: Sequence[bool] | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Standard-normal noise [N, B, A] for the current and the next actions; with per-seed
        generators, only the seeds `drawing` (host-side, default all) draw (the others get zeros and
        their streams stay where they are)."""
        if self.generators is None:
            return torch.randn_like(like), torch.randn_like(like)
        drawing = [True] * len(self.generators) if drawing is None else list(drawing)
        # Seed i's two draws in its one-seed order: current actions, then next actions.
        draws = [
            [
                torch.empty_like(like[0]).normal_(generator=g) if draw else torch.zeros_like(like[0])
                for _ in range(2)
            ]
            for g, draw in zip(self.generators, drawing, strict=True)
        ]
        return torch.stack([d[0] for d in draws]), torch.stack([d[1] for d in draws])

    def step(
        self,
        batch: Mapping[str, torch.Tensor],
        active: torch.Tensor | None = None,
        drawing: Sequence[bool] | None = None,
    ) -> dict[str, torch.Tensor]:
        """One gradient step for every seed; `batch` columns are [N, B, ...]. `active` ([N] bool, default
        all): the seeds that take this step; the others keep everything, as a skipped seed does, but are
        not counted as skipped (a seed that owes fewer updates than the stack runs). `drawing` (host
        bools, with per-seed generators): the seeds that draw noise, so an inactive seed's stream does
        not move (pass the host twin of `active`). Returns each loss statistic, `total_loss` and
        `finite` as [N] device tensors."""
        self.agents.flat.grad = None
        actions = batch[Columns.ACTIONS]
        noise, noise_next = self._noise(actions, drawing)
        fwd_out = self.agents.forward_train(batch, noise, noise_next)
        loss_batch = {k: batch[k] for k in LOSS_COLUMNS if k in batch}

        def one_seed(fwd, cols, log_alpha):
            return sac_losses(
                fwd,
                cols,
                log_alpha,
                self.target_entropy,
                gamma=self.gamma,
                critic_loss=self.critic_loss,
                twin_q=True,
            )

        total, stats = torch.func.vmap(one_seed)(fwd_out, loss_batch, self.agents.log_alpha)
        total.sum().backward()
        finite = torch.isfinite(self.agents.flat.grad).all(1)
        steps = finite if active is None else finite & active
        self.optimizer.step(steps)
        with torch.no_grad():
            critics = self.agents.flat[:, : self.agents.num_critic_params]
            self.agents.target_flat.lerp_(critics, (steps * self.tau).unsqueeze(1))
            self.skipped.add_(torch.logical_not(finite) if active is None else active & ~finite)
        stats = dict(stats)
        stats[TOTAL_LOSS] = total.detach()
        stats[FINITE] = finite
        return stats


def stack_batches(batches: Sequence[Mapping[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """N one-seed batches (same columns and sizes) as one batch with a leading seed axis."""
    return {k: torch.stack([b[k] for b in batches]) for k in batches[0]}
