"""A fast SAC torch Learner: one backward pass, per-gradient-step target updates, a cheap NaN guard.

It is still an RLlib `Learner` (a subclass of `SACTorchLearner`): `LearnerGroup.update(batch=...)` or
`update(episodes=...)`, local or remote learners, checkpoints (`get_state`/`set_state`) and weight
sync to env runners all work as for the stock learner. What differs from `SACTorchLearner`:

* The actor, critic(s) and temperature losses are summed and back-propagated once (the stock learner
  calls `backward(retain_graph=True)` once per optimizer). Gradients are identical: each loss only
  reaches its own parameters (the actor loss sees the critics with `requires_grad=False`, targets and
  `alpha` in the actor/critic losses are detached).
* Target networks are Polyak-updated after *every gradient step* (every minibatch) with `config.tau`,
  like SB3, instead of once per `update()` call. A call with N minibatches therefore moves the targets
  N times. `target_network_update_freq` is ignored (it counts env steps, which do not advance within
  one call). LR schedules still step once per call (they are keyed on sampled env steps, which is
  right).
* NaN guard: one fused finite-check over all gradients per step; a non-finite step is skipped (no
  optimizer step, no target update) and counted in the `num_nonfinite_steps_skipped` metric. Use with
  `torch_skip_nan_gradients=True`, which turns off RLlib's per-parameter checks.
* The critic and twin critic share one Adam optimizer ("qf"); Adam runs fused where torch allows.
* log(alpha) is part of the learner state (stock RLlib 2.60 drops it from checkpoints).
* Loss: `weights` and `n_step` columns are optional (ones when absent), so a flat replay batch needs
  only obs, new_obs, actions, rewards, terminateds. The critic loss is RLlib's Huber loss by default
  or SB3's 0.5 * MSE with `learner_config_dict["gc_sac"]["critic_loss"] = "mse"`.

Knobs live in `config.learner_config_dict["gc_sac"]` (see `config.use_fast_learner`):
`critic_loss` ("huber" | "mse"), `torch_threads` (int or None).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.algorithms.dqn.dqn_learner import DQNLearner
from ray.rllib.algorithms.sac.sac_learner import (
    LOGPS_KEY,
    QF_LOSS_KEY,
    QF_MAX_KEY,
    QF_MEAN_KEY,
    QF_MIN_KEY,
    QF_PREDS,
    QF_TWIN_LOSS_KEY,
    QF_TWIN_PREDS,
    TD_ERROR_MEAN_KEY,
    SACLearner,
)
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core import COMPONENT_OPTIMIZER
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY, Learner
from ray.rllib.core.learner.torch.torch_learner import TorchLearner
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import ALL_MODULES, NUM_TARGET_UPDATES

from copilot_ray.torch_checks import all_finite

GC_SAC_KEY = "gc_sac"
NONFINITE_SKIPPED_KEY = "num_nonfinite_steps_skipped"
LOG_ALPHA_STATE_KEY = "gc_sac_log_alpha"


def gc_sac_settings(config) -> dict[str, Any]:
    """The `learner_config_dict["gc_sac"]` settings of an AlgorithmConfig, with defaults."""
    d = dict((getattr(config, "learner_config_dict", None) or {}).get(GC_SAC_KEY, {}))
    d.setdefault("critic_loss", "huber")
    d.setdefault("torch_threads", None)
    if d["critic_loss"] not in ("huber", "mse"):
        raise ValueError(
            f"learner_config_dict['gc_sac']['critic_loss'] must be 'huber' or 'mse', got {d['critic_loss']!r}"
        )
    return d


def bellman_target(
    rewards: torch.Tensor,
    terminateds: torch.Tensor,
    q_target_next: torch.Tensor,
    logp_next: torch.Tensor,
    alpha: torch.Tensor,
    gamma: float,
    n_step: torch.Tensor | None = None,
) -> torch.Tensor:
    """y = r + gamma^n * (1 - terminated) * (min_i Q'_i(s', a') - alpha * log pi(a'|s')), detached."""
    discount = gamma if n_step is None else gamma ** n_step.float()
    v_next = q_target_next - alpha.detach() * logp_next
    return (rewards.float() + discount * (1.0 - terminateds.float()) * v_next).detach()


class GCSACTorchLearner(SACTorchLearner):
    """SAC torch learner tuned for many small updates; see the module docstring."""

    @override(SACTorchLearner)
    def build(self) -> None:
        """Reads the `gc_sac` settings, sets torch's thread count, then `SACTorchLearner.build`."""
        settings = gc_sac_settings(self.config)
        if settings["torch_threads"]:
            torch.set_num_threads(int(settings["torch_threads"]))
        self._gc_settings = settings
        self._gc_target_pairs: dict[str, tuple[list[torch.Tensor], list[torch.Tensor]]] = {}
        super().build()

    # ------------------------------------------------------------------ optimizers
    @override(SACTorchLearner)
    def configure_optimizers_for_module(self, module_id, config=None) -> None:
        """Box actions: one Adam each for "qf" (both critics), "policy" and "alpha"; else SAC's own."""
        module = self._module[module_id]
        if not isinstance(module.action_space, gym.spaces.Box):
            return super().configure_optimizers_for_module(module_id, config)

        def adam(params):
            # Fused Adam (one kernel per step for all params) where torch supports it on this device.
            try:
                return torch.optim.Adam(params, eps=1e-7, fused=True)
            except (RuntimeError, ValueError):
                return torch.optim.Adam(params, eps=1e-7, foreach=True)

        params_critic = self.get_parameters(module.qf_encoder) + self.get_parameters(module.qf)
        if config.twin_q:
            params_critic += self.get_parameters(module.qf_twin_encoder) + self.get_parameters(module.qf_twin)
        params_actor = self.get_parameters(module.pi_encoder) + self.get_parameters(module.pi)
        for name, params, lr in (
            ("qf", params_critic, config.critic_lr),
            ("policy", params_actor, config.actor_lr),
            ("alpha", [self.curr_log_alpha[module_id]], config.alpha_lr),
        ):
            self.register_optimizer(
                module_id=module_id,
                optimizer_name=name,
                optimizer=adam(params),
                params=params,
                lr_or_lr_schedule=lr,
            )

    # ------------------------------------------------------------------ loss
    @override(SACTorchLearner)
    def _compute_loss_for_module_continuous(self, *, module_id, config, batch, fwd_out):
        alpha = torch.exp(self.curr_log_alpha[module_id])
        q1 = fwd_out[QF_PREDS]
        target = bellman_target(
            batch[Columns.REWARDS],
            batch[Columns.TERMINATEDS],
            fwd_out["q_target_next"],
            fwd_out["logp_next_resampled"],
            alpha,
            config.gamma,
            batch.get("n_step"),
        )
        weights = batch.get("weights")

        def critic_loss_fn(q):
            if self._gc_settings["critic_loss"] == "mse":
                per_item = 0.5 * (q - target) ** 2
            else:
                per_item = torch.nn.functional.huber_loss(q, target, reduction="none", delta=1.0)
            return torch.mean(per_item if weights is None else weights * per_item)

        critic_loss = critic_loss_fn(q1)
        total_critic = critic_loss
        td_error = torch.abs(q1 - target)
        if config.twin_q:
            q2 = fwd_out[QF_TWIN_PREDS]
            critic_twin_loss = critic_loss_fn(q2)
            total_critic = critic_loss + critic_twin_loss
            td_error = 0.5 * (td_error + torch.abs(q2 - target))

        logp = fwd_out["logp_resampled"]
        actor_loss = torch.mean(alpha.detach() * logp - fwd_out["q_curr"])
        alpha_loss = -torch.mean(
            self.curr_log_alpha[module_id] * (logp.detach() + self.target_entropy[module_id])
        )

        with torch.no_grad():
            q_curr = fwd_out["q_curr"]
            stats = {
                POLICY_LOSS_KEY: actor_loss,
                QF_LOSS_KEY: critic_loss,
                "alpha_loss": alpha_loss,
                "alpha_value": alpha[0],
                "log_alpha_value": self.curr_log_alpha[module_id][0],
                "target_entropy": self.target_entropy[module_id],
                LOGPS_KEY: torch.mean(logp),
                QF_MEAN_KEY: torch.mean(q_curr),
                QF_MAX_KEY: torch.max(q_curr),
                QF_MIN_KEY: torch.min(q_curr),
                TD_ERROR_MEAN_KEY: torch.mean(td_error),
            }
            if config.twin_q:
                stats[QF_TWIN_LOSS_KEY] = critic_twin_loss
        self.metrics.log_dict({k: v.detach() for k, v in stats.items()}, key=module_id, window=1)
        return actor_loss + total_critic + alpha_loss

    # ------------------------------------------------------------------ update step
    @override(SACTorchLearner)
    def compute_gradients(self, loss_per_module, **kwargs):
        """One backward pass over the summed losses (TorchLearner's default), not one per optimizer."""
        self._temp_losses.clear()
        return TorchLearner.compute_gradients(self, loss_per_module, **kwargs)

    @override(TorchLearner)
    def _uncompiled_update(self, batch: dict, **kwargs):
        fwd_out = self.module.forward_train(batch)
        loss_per_module = self.compute_losses(fwd_out=fwd_out, batch=batch)
        gradients = self.compute_gradients(loss_per_module)
        gradients = self.postprocess_gradients(gradients)
        if all_finite(gradients.values()):
            self.apply_gradients(gradients)
            self._polyak_update_targets()
        else:
            for optim in self._optimizer_parameters:
                optim.zero_grad(set_to_none=True)
            self.metrics.log_value((ALL_MODULES, NONFINITE_SKIPPED_KEY), 1, reduce="lifetime_sum")
        return fwd_out, loss_per_module, {}

    def _target_pairs(self, module_id) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        pairs = self._gc_target_pairs.get(module_id)
        if pairs is None:
            module = self.module[module_id].unwrapped()
            main, target = [], []
            for main_net, target_net in module.get_target_network_pairs():
                main += [p.data for p in main_net.parameters()]
                target += [p.data for p in target_net.parameters()]
            pairs = (main, target)
            self._gc_target_pairs[module_id] = pairs
        return pairs

    @torch.no_grad()
    def _polyak_update_targets(self) -> None:
        for module_id, module in self.module._rl_modules.items():
            if not isinstance(module.unwrapped(), TargetNetworkAPI):
                continue
            main, target = self._target_pairs(module_id)
            # target <- target + tau * (main - target)
            torch._foreach_lerp_(target, main, float(self.config.get_config_for_module(module_id).tau))
            self.metrics.log_value((module_id, NUM_TARGET_UPDATES), 1, reduce="lifetime_sum")

    @override(DQNLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        """TorchLearner's lr-schedule stepping and logging, without DQNLearner's target update."""
        # Skip DQNLearner's once-per-call target update (targets move per gradient step above).
        TorchLearner.after_gradient_based_update(self, timesteps=timesteps)

    # Module set changes invalidate cached target-parameter lists.
    @override(SACLearner)
    def add_module(self, **kwargs):
        """SACLearner's `add_module`, dropping the cached target-parameter lists."""
        self._gc_target_pairs.clear()
        return super().add_module(**kwargs)

    @override(SACLearner)
    def remove_module(self, module_id, **kwargs):
        """SACLearner's `remove_module`, dropping the cached target-parameter lists."""
        self._gc_target_pairs.clear()
        return super().remove_module(module_id, **kwargs)

    # RLlib 2.60's SACLearner keeps log(alpha) outside the RLModule and leaves it out of its state,
    # so a restored stock learner restarts from `initial_alpha`. Keep it with the optimizer state.
    @override(Learner)
    def get_state(self, components=None, *, not_components=None, **kwargs):
        """Learner's state plus log(alpha) per module (with the optimizer component)."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        if self._check_component(COMPONENT_OPTIMIZER, components, not_components):
            state[LOG_ALPHA_STATE_KEY] = {
                mid: v.detach().cpu().numpy().copy() for mid, v in self.curr_log_alpha.items()
            }
        return state

    @override(Learner)
    def set_state(self, state) -> None:
        """Learner's `set_state`, also restoring log(alpha) when the state has it."""
        super().set_state(state)
        with torch.no_grad():
            for mid, value in (state.get(LOG_ALPHA_STATE_KEY) or {}).items():
                if mid in self.curr_log_alpha:
                    self.curr_log_alpha[mid].copy_(torch.as_tensor(value))
        self._gc_target_pairs.clear()
