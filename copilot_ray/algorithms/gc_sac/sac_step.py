"""The SAC gradient step of N seeds' agents at once, with no host synchronisation inside: the agent's
fused update (a one-seed run is N = 1).

`SACStep(modules, log_alphas, optimizers, ...)` takes N `catalog.GCSACTorchRLModule`s of one shape (one
per seed) and keeps every trained number of seed i in row i of one leaf tensor `flat` [N, P] (critics,
then actor, then log alpha) and its target critics in `target_flat` [N, P_critics]. The modules' own
parameters, their log alphas and their Adam optimizers' moments and step counts become views into
those rows, so a module is always its seed's current agent: weight sync to env runners and the one-seed
checkpoint format need no copying.

`step(batch)` (columns [N, B, ...], seed i reading row i) does what `GCSACTorchLearner`'s RLlib path does
per minibatch, for every seed:

* the forward pass is the RLModule's own networks (`torch.func.functional_call` on its encoders and
  heads) and its own action distribution, evaluated over the stacked parameters under `torch.vmap`
  (at N = 1 called on the one seed's parameters directly: on a CPU a vmapped linear layer measured
  twice an unbatched one); the losses are `losses.sac_losses`, vmapped too: each seed averages over its
  own batch, and the sum over seeds back-propagates each seed's gradient into its own row;
* the reparameterisation noise comes from the seeds' own `philox.PhiloxStreams` (seed i's noise is the
  same in a stack of any size, on any device);
* Adam is torch's fused Adam kernel, called per seed and optimizer group on views of the seed's row,
  with the seed's own step counts and its own skip flag (`found_inf`);
* the finite check is per seed and stays on the device: a seed with a non-finite gradient keeps its
  parameters, moments, step count and target critics, and its entry of `skipped` goes up; `active`
  ([N] bool) leaves the other seeds untouched the same way without counting them as skipped.

No `.item()`, no host-built tensor, no data-dependent shape: the step can be captured in one CUDA graph
(`graph_capture.py`) and replayed. `replay_step_call` is where every SAC update is captured, one
seed's (the learner's fused update) and a seed stack's alike.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.sac.sac_learner import QF_PREDS, QF_TWIN_PREDS
from ray.rllib.core.columns import Columns
from ray.rllib.core.models.base import ENCODER_OUT
from torch.fx.experimental.proxy_tensor import make_fx

from copilot_ray.algorithms.gc_sac.graph_capture import CapturedCall
from copilot_ray.algorithms.gc_sac.losses import sac_losses
from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.replay_buffer import TRAIN_COLUMNS

TOTAL_LOSS = "total_loss"
FINITE = "finite"
CRITIC_NETS = ("qf_encoder", "qf", "qf_twin_encoder", "qf_twin")
ACTOR_NETS = ("pi_encoder", "pi")
TARGET_NETS = tuple("target_" + net for net in CRITIC_NETS)
LOSS_COLUMNS = (Columns.REWARDS, Columns.TERMINATEDS, "weights", "n_step")
# The purpose word of the seeds' reparameterisation-noise streams (`PhiloxStreams`).
NOISE_STREAM = 1
# For N > 1 a parameter's gradient is a strided view of the step's gradient rows, on purpose (autograd
# accumulates into it in place); torch warns that such a layout "may impair performance".
warnings.filterwarnings("ignore", message="grad and param do not obey the gradient layout contract")


def _layout(module: torch.nn.Module, nets: Sequence[str], start: int = 0) -> tuple[list[tuple], int]:
    """[(net, parameter name, shape, first, end)] of `nets`' parameters laid end to end from `start`."""
    out, at = [], start
    for net in nets:
        for name, p in getattr(module, net).named_parameters():
            out.append((net, name, tuple(p.shape), at, at + p.numel()))
            at += p.numel()
    return out, at


def _parameters(module: torch.nn.Module, layout: Sequence[tuple]) -> list[torch.nn.Parameter]:
    return [dict(getattr(module, net).named_parameters())[name] for net, name, *_ in layout]


class SACStep:
    """N seeds' SAC step (module docstring).

    Args:
        modules: one `GCSACTorchRLModule` per seed (continuous actions, twin critics, same shapes).
        log_alphas: each seed's log(alpha) ([1] tensors: the learner's temperature parameters).
        optimizers: each seed's (critics, actor, temperature) Adam optimizers, or None; their
            learning rates are the step's, and their moments and step counts become views of the
            step's (so a learner's checkpoint holds them). Without optimizers, `lrs` gives the rates.
        target_entropy: SAC's entropy target; gamma, tau: discount and Polyak rate.
        critic_loss: "huber" or "mse".
        seeds: each seed's number (keys its noise stream).
        lrs: {"qf", "policy", "alpha"} learning rates, when `optimizers` is None.
    """

    def __init__(
        self,
        modules: Sequence[torch.nn.Module],
        log_alphas: Sequence[torch.Tensor],
        optimizers: Sequence[Sequence[torch.optim.Optimizer]] | None,
        target_entropy: torch.Tensor | float,
        *,
        gamma: float,
        tau: float,
        critic_loss: str,
        seeds: Sequence[int],
        lrs: Mapping[str, float] | None = None,
    ):
        if not modules or len(modules) != len(log_alphas) or len(modules) != len(seeds):
            raise ValueError(
                f"need one log alpha and one seed per module, got {len(modules)} modules, "
                f"{len(log_alphas)} log alphas, {len(seeds)} seeds"
            )
        if not all(getattr(m, "twin_q", False) for m in modules):
            raise ValueError("the SAC step needs twin critics (twin_q=True)")
        self.module = modules[0]  # the network implementation; every seed's rows go through it
        self.num_seeds = len(modules)
        # A device tensor made once: a host number would enter the step as a new tensor each call.
        self.target_entropy = torch.as_tensor(
            target_entropy, dtype=torch.float32, device=log_alphas[0].device
        )
        self.gamma, self.tau, self.critic_loss = float(gamma), float(tau), critic_loss
        self.critic_layout, self.num_critic_params = _layout(self.module, CRITIC_NETS)
        self.actor_layout, actor_end = _layout(self.module, ACTOR_NETS, self.num_critic_params)
        self.target_layout, _ = _layout(self.module, TARGET_NETS)
        self.num_params = actor_end + 1  # and log alpha last
        alpha_shape = tuple(log_alphas[0].shape)
        self.layout = (
            self.critic_layout
            + self.actor_layout
            + [(None, "log_alpha", alpha_shape, actor_end, actor_end + 1)]
        )
        device = log_alphas[0].device
        self.device = device
        self._dist_cls = self.module.get_train_action_dist_cls()
        self._slots = {}  # (net, parameter name) -> (the module that holds it, its attribute)
        for net, name, *_ in self.critic_layout + self.actor_layout + self.target_layout:
            owner, _, attr = name.rpartition(".")
            self._slots[(net, name)] = (getattr(self.module, net).get_submodule(owner), attr)
        self._traced_acts: dict[tuple, torch.fx.GraphModule] = {}  # `act`'s graphs, by input shape

        with torch.no_grad():
            self.flat = torch.stack([self._row(m, a) for m, a in zip(modules, log_alphas, strict=True)])
            self.target_flat = torch.stack(
                [
                    torch.cat([p.detach().reshape(-1) for p in _parameters(m, self.target_layout)])
                    for m in modules
                ]
            )
        self.flat_grad = torch.zeros_like(self.flat)
        self.exp_avg = torch.zeros_like(self.flat)
        self.exp_avg_sq = torch.zeros_like(self.flat)
        # Autograd's leaves: each parameter of every seed as one [N, ...] view of `flat`, its gradient a
        # view of `flat_grad` (accumulated in place), so one finite check and one Polyak update cover all.
        n = self.num_seeds
        self.leaves = [
            self._stacked_view(self.flat, a, b, shape).requires_grad_() for *_, shape, a, b in self.layout
        ]
        for leaf, (*_, shape, a, b) in zip(self.leaves, self.layout, strict=True):
            leaf.grad = self._stacked_view(self.flat_grad, a, b, shape)
        self.targets = [
            self._stacked_view(self.target_flat, a, b, shape) for *_, shape, a, b in self.target_layout
        ]
        # A step count per seed and parameter, as torch's Adam keeps them (bumped for the seeds that step).
        self.step_counts = torch.zeros(n, len(self.layout), device=device)
        self.skipped = torch.zeros(n, dtype=torch.int64, device=device)
        groups = {
            "qf": range(len(self.critic_layout)),
            "policy": range(len(self.critic_layout), len(self.layout) - 1),
            "alpha": range(len(self.layout) - 1, len(self.layout)),
        }
        self.betas, self.eps = (0.9, 0.999), 1e-7
        if optimizers is not None:
            if len(optimizers) != n:
                raise ValueError(f"need the optimizers of every seed ({n}), got {len(optimizers)}")
            first = [o.param_groups[0] for o in optimizers[0]]
            lrs = {name: float(g["lr"]) for name, g in zip(groups, first, strict=True)}
            self.betas, self.eps = tuple(first[0]["betas"]), float(first[0]["eps"])
        if lrs is None:
            raise ValueError("need the optimizers or the learning rates")
        self.lrs = {name: float(lrs[name]) for name in groups}
        # Per seed and group: the lists torch's fused Adam kernel takes (views of the seed's rows).
        self._adam_lists = [
            {name: self._adam_views(i, idx) for name, idx in groups.items()} for i in range(n)
        ]
        self.noise = PhiloxStreams(seeds, NOISE_STREAM, device)
        self._view_into_rows(modules, log_alphas, optimizers)

    # ------------------------------------------------------------------ storage
    def _row(self, module, log_alpha) -> torch.Tensor:
        params = _parameters(module, self.critic_layout) + _parameters(module, self.actor_layout)
        return torch.cat([p.detach().reshape(-1) for p in params] + [log_alpha.detach().reshape(1)])

    def _stacked_view(self, storage: torch.Tensor, a: int, b: int, shape) -> torch.Tensor:
        """Columns a:b of every seed's row as [N, *shape]; at N = 1 as the one seed's [*shape]."""
        if self.num_seeds == 1:
            return storage[0, a:b].view(shape)
        return storage[:, a:b].view(self.num_seeds, *shape)

    def _adam_views(self, i: int, indices) -> dict[str, list[torch.Tensor]]:
        entries = [self.layout[k] for k in indices]
        return {
            "params": [self.flat[i, a:b] for *_, a, b in entries],
            "grads": [self.flat_grad[i, a:b] for *_, a, b in entries],
            "exp_avgs": [self.exp_avg[i, a:b] for *_, a, b in entries],
            "exp_avg_sqs": [self.exp_avg_sq[i, a:b] for *_, a, b in entries],
            "state_steps": [self.step_counts[i, k] for k in indices],
        }

    def _view_into_rows(self, modules, log_alphas, optimizers) -> None:
        """Points seed i's parameters, log alpha and Adam state at row i of the step's storage (the
        optimizers' current moments and counts copied in first)."""
        flat, target, layout = self.flat, self.target_flat, self.critic_layout + self.actor_layout
        for i, module in enumerate(modules):
            params = _parameters(module, layout)
            if optimizers is not None:
                self._adopt_adam_state(i, optimizers[i], params, log_alphas[i])
            for p, (_, _, shape, a, b) in zip(params, layout, strict=True):
                p.data = flat[i, a:b].view(shape)
            for p, (_, _, shape, a, b) in zip(
                _parameters(module, self.target_layout), self.target_layout, strict=True
            ):
                p.data = target[i, a:b].view(shape)
            log_alphas[i].data = flat[i, -1:].view(log_alphas[i].shape)

    def _adopt_adam_state(self, i: int, optimizers, params, log_alpha) -> None:
        """Seed i's optimizers' moments and step counts copied into its rows, then their state made
        views of those rows (what the learner checkpoints, and what its RLlib path steps)."""
        column_of = {id(p): k for k, p in enumerate([*params, log_alpha])}
        with torch.no_grad():
            for optimizer in optimizers:
                for p in _adam_params(optimizer):
                    if id(p) not in column_of:
                        raise ValueError(
                            "an optimizer steps a parameter that is not the seed's actor, critics or log alpha"
                        )
                    k = column_of[id(p)]
                    *_, shape, a, b = self.layout[k]
                    state = optimizer.state[p]
                    if state:
                        self.exp_avg[i, a:b].copy_(state["exp_avg"].reshape(-1))
                        self.exp_avg_sq[i, a:b].copy_(state["exp_avg_sq"].reshape(-1))
                        self.step_counts[i, k] = state["step"]
                    state["exp_avg"] = self.exp_avg[i, a:b].view(shape)
                    state["exp_avg_sq"] = self.exp_avg_sq[i, a:b].view(shape)
                    state["step"] = self.step_counts[i, k]

    def set_learning_rates(self, lrs: Mapping[str, float]) -> None:
        """The {"qf", "policy", "alpha"} learning rates (host numbers: a graph captured before keeps the
        old ones, so a change needs a new capture)."""
        self.lrs = {name: float(lrs[name]) for name in self.lrs}

    @contextlib.contextmanager
    def _bound(self, layout: Sequence[tuple], tensors: Sequence[torch.Tensor]):
        """The module's parameters of `layout` replaced by `tensors` (one seed's, or vmapped ones) while
        inside: what `torch.func.functional_call` does, without its per-call bookkeeping (measured
        about 50 us a call on a CPU, 16 calls a step)."""
        slots = [self._slots[(net, name)] for net, name, *_ in layout]
        before = [owner._parameters[attr] for owner, attr in slots]  # noqa: SLF001
        for (owner, attr), tensor in zip(slots, tensors, strict=True):
            owner._parameters[attr] = tensor  # noqa: SLF001
        try:
            yield
        finally:
            for (owner, attr), tensor in zip(slots, before, strict=True):
                owner._parameters[attr] = tensor  # noqa: SLF001

    def _call(self, net: str, inputs):
        return getattr(self.module, net)(inputs)

    def _q(self, prefix: str, obs, actions) -> tuple[torch.Tensor, torch.Tensor]:
        """(Q1, Q2) of the online (prefix "") or target ("target_") critics, as the module's
        `_qf_forward_train_helper` computes them."""
        q_in = {Columns.OBS: obs, Columns.ACTIONS: actions}
        return tuple(
            self._call(prefix + head, self._call(prefix + head + "_encoder", q_in)[ENCODER_OUT]).squeeze(-1)
            for head in ("qf", "qf_twin")
        )

    def _sample(self, obs, noise):
        """(logits, the module's own distribution, its Gaussian sample before squashing) with `noise`
        (as torch's Normal.rsample takes it: loc + noise * scale)."""
        logits = self._call("pi", self._call("pi_encoder", {Columns.OBS: obs})[ENCODER_OUT])
        dist = self._dist_cls.from_logits(logits)
        gaussian = dist._dist  # noqa: SLF001 - the distribution's Normal, to sample it with given noise
        return logits, dist, gaussian.loc + noise * gaussian.scale

    def _policy(self, obs, noise):
        """(logits, squashed action, its log-probability) of `_sample`."""
        logits, dist, unsquashed = self._sample(obs, noise)
        return logits, dist._squash(unsquashed), dist._squashed_logp(unsquashed)  # noqa: SLF001

    def _forward_train(self, params, targets, batch, noise, noise_next) -> dict[str, torch.Tensor]:
        """`GCSACTorchRLModule._forward_train_continuous` of one seed, with its noise given."""
        obs, next_obs = batch[Columns.OBS], batch[Columns.NEXT_OBS]
        critics = len(self.critic_layout)
        out = {}
        with self._bound(self.layout[:-1], params[:-1]), self._bound(self.target_layout, targets):
            out[QF_PREDS], out[QF_TWIN_PREDS] = self._q("", obs, batch[Columns.ACTIONS])
            _, actions_new, out["logp_resampled"] = self._policy(obs, noise)
            # The critics at the fresh actions pass gradients to the actor only.
            with self._bound(self.critic_layout, [p.detach() for p in params[:critics]]):
                out["q_curr"] = torch.min(*self._q("", obs, actions_new))
            with torch.no_grad():
                _, actions_next, out["logp_next_resampled"] = self._policy(next_obs, noise_next)
                out["q_target_next"] = torch.min(*self._q("target_", next_obs, actions_next))
        return out

    def _losses(self, params, targets, batch, noise, noise_next):
        """One seed's (total loss, statistics)."""
        fwd_out = self._forward_train(params, targets, batch, noise, noise_next)
        return sac_losses(
            fwd_out,
            {k: batch[k] for k in LOSS_COLUMNS if k in batch},
            params[-1],
            self.target_entropy,
            gamma=self.gamma,
            critic_loss=self.critic_loss,
            twin_q=True,
        )

    def _per_seed(self, fn, weights: tuple, *stacked):
        """`fn(*weights, *stacked)` for every seed, results stacked: vmapped over `weights` (lists of
        the step's stacked views: leaves, targets) and `stacked` (pytrees with a leading seed axis); at
        N = 1 called on the one seed's tensors (its views have no seed axis)."""
        if self.num_seeds > 1:
            return torch.vmap(fn)(*weights, *stacked)
        tree_map = torch.utils._pytree.tree_map  # noqa: SLF001 - torch's own pytree helpers
        out = fn(*weights, *tree_map(lambda t: t.squeeze(0), stacked))
        return tree_map(lambda t: t.unsqueeze(0), out)

    # ------------------------------------------------------------------ the step
    def step(
        self, batch: Mapping[str, torch.Tensor], active: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """One gradient step for every seed (`active` [N] bool: only those; default all); `batch`
        columns are [N, B, ...]. Returns each loss statistic, `total_loss` and `finite` as [N] device
        tensors."""
        actions = batch[Columns.ACTIONS]
        if actions.dim() != 3 or actions.shape[0] != self.num_seeds:  # shapes are host metadata: no sync
            raise ValueError(
                f"the SAC step takes [N, B, ...] columns for its {self.num_seeds} seed(s); got actions of "
                f"shape {tuple(actions.shape)}"
            )
        # Seed i's two draws in one: the current actions' noise, then the next actions'.
        noise = self.noise.normal((2, *actions.shape[1:]), active)
        total, stats = self._per_seed(
            self._losses, (self.leaves, self.targets), dict(batch), noise[:, 0], noise[:, 1]
        )
        self.flat_grad.zero_()
        total.sum().backward()
        # One reduction: a sum is finite iff every term is (short of overflowing past 3e38).
        finite = torch.isfinite(self.flat_grad.sum(1))
        steps = finite if active is None else finite & active
        with torch.no_grad():
            self._adam(steps)
            critics = self.flat[:, : self.num_critic_params]
            self.target_flat.lerp_(critics, (steps * self.tau).unsqueeze(1))
            self.skipped.add_(torch.logical_not(finite) if active is None else active & ~finite)
        stats = dict(stats)
        stats[TOTAL_LOSS] = total.detach()
        stats[FINITE] = finite
        return stats

    def _adam(self, ok: torch.Tensor) -> None:
        """torch's fused Adam on each seed's rows, skipped (`found_inf`) where `ok` [N] is False: that
        seed's parameters, moments and step counts stay as they are."""
        self.step_counts.add_(ok.unsqueeze(1))  # torch's Adam counts the step before its kernel runs
        skip = torch.logical_not(ok).float()
        beta1, beta2 = self.betas
        for i, groups in enumerate(self._adam_lists):
            for name, lists in groups.items():
                torch._fused_adam_(  # noqa: SLF001 - the kernel torch.optim.Adam(fused=True) runs
                    lists["params"],
                    lists["grads"],
                    lists["exp_avgs"],
                    lists["exp_avg_sqs"],
                    [],
                    lists["state_steps"],
                    lr=self.lrs[name],
                    beta1=beta1,
                    beta2=beta2,
                    weight_decay=0.0,
                    eps=self.eps,
                    amsgrad=False,
                    maximize=False,
                    grad_scale=None,
                    found_inf=skip[i],
                )

    # ------------------------------------------------------------------ acting
    @torch.no_grad()
    def act(self, obs: torch.Tensor, noise: torch.Tensor | None = None) -> torch.Tensor:
        """Every seed's actions for its own observations `obs` [N, E, d] in one batched forward pass of
        the modules' actor: with standard-normal `noise` [N, E, A] a sample of its squashed Gaussian,
        without it the distribution's deterministic action (RLlib's: the mean, before squashing).

        For N > 1 the vmapped actor is traced once per input shape into a graph of the aten ops vmap
        dispatches (`make_fx`; the actor's parameters are its inputs, so it acts with the current
        weights) and the graph is replayed: the same kernels on the same numbers, without vmap's
        per-op batching in Python, which at one row per seed cost about half the traversal's host
        time (`benchmarks/stacked_trial.py`)."""
        actor = self.leaves[len(self.critic_layout) : len(self.critic_layout) + len(self.actor_layout)]
        # (make_fx counts a function's positional arguments from its code: a plain function each)
        if noise is None:
            inputs, one_seed = (obs,), lambda params, o: self._act_one_seed(params, o, None)
        else:
            inputs, one_seed = (obs, noise), lambda params, o, z: self._act_one_seed(params, o, z)
        if self.num_seeds == 1:
            return self._per_seed(one_seed, (actor,), *inputs)
        key = (tuple(obs.shape), noise is None, obs.device, obs.dtype)
        traced = self._traced_acts.get(key)
        if traced is None:
            traced = make_fx(torch.vmap(one_seed))(list(actor), *inputs)
            baked = [node.target for node in traced.graph.nodes if node.op == "get_attr"]
            if baked:  # a tensor the trace read from outside its inputs would stay at its traced value
                raise RuntimeError(f"the traced actor holds tensors that are not its inputs: {baked}")
            self._traced_acts[key] = traced
        return traced(list(actor), *inputs)

    def _act_one_seed(self, params, obs, noise):
        """One seed's action (`act`) with its actor's parameters `params`."""
        with self._bound(self.actor_layout, params):
            if noise is None:
                logits = self._call("pi", self._call("pi_encoder", {Columns.OBS: obs})[ENCODER_OUT])
                return logits.chunk(2, dim=-1)[0]
            _, dist, unsquashed = self._sample(obs, noise)  # acting needs no log-probability
            return dist._squash(unsquashed)  # noqa: SLF001

    # ------------------------------------------------------------------ checkpoints
    def get_state(self) -> dict[str, Any]:
        """Every seed's parameters, targets, Adam moments and counts, skips and noise counters (numpy)."""
        state = {k: v.detach().cpu().numpy().copy() for k, v in self._tensors().items()}
        state["noise"] = self.noise.get_state()
        return state

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores `get_state`'s snapshot in place (the tensors keep their storage, so the modules'
        views and a captured graph stay valid); a snapshot of another shape is refused first."""
        tensors = self._tensors()
        for key, tensor in tensors.items():
            shape = tuple(np.shape(state[key]))
            if shape != tuple(tensor.shape):
                raise ValueError(
                    f"SAC step state: {key} has shape {shape}, this step's is {tuple(tensor.shape)} "
                    f"({self.num_seeds} seeds)"
                )
        with torch.no_grad():
            for key, tensor in tensors.items():
                tensor.copy_(torch.as_tensor(state[key]))
        self.noise.set_state(state["noise"])

    def _tensors(self) -> dict[str, torch.Tensor]:
        return {
            "flat": self.flat,
            "target_flat": self.target_flat,
            "exp_avg": self.exp_avg,
            "exp_avg_sq": self.exp_avg_sq,
            "step_counts": self.step_counts,
            "skipped": self.skipped,
        }


def _adam_params(optimizer: torch.optim.Optimizer) -> list[torch.Tensor]:
    return [p for group in optimizer.param_groups for p in group["params"]]


def replay_step_call(
    step: SACStep,
    replay: Any,
    batch_size: int,
    *,
    capture: bool,
    compile_update: bool = False,
    active: torch.Tensor | None = None,
):
    """The zero-argument call of one `step` on a batch sampled from `replay` (a device buffer with a
    ring per seed) inside it: the seeds `active` ([N] bool, written in place between calls; None: all)
    sample and step. Compiled first with `compile_update`; with `capture` (a CUDA device's, unless its
    `cuda_graph` knob is off) captured into one graph and replayed (`CapturedCall`): the capture site
    of every SAC update."""

    def run() -> dict[str, torch.Tensor]:
        return step.step(replay.sample(int(batch_size), TRAIN_COLUMNS, active), active=active)

    if compile_update:
        run = torch.compile(run)
    if capture:
        run = CapturedCall(run)
    return run


def stack_batches(batches: Sequence[Mapping[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    """N one-seed batches (same columns and sizes) as one batch with a leading seed axis."""
    return {k: torch.stack([b[k] for b in batches]) for k in batches[0]}


def with_seed_axis(batch: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """A one-seed batch [B, ...] as the N = 1 batch [1, B, ...] the step takes."""
    return {k: v.unsqueeze(0) for k, v in batch.items()}
