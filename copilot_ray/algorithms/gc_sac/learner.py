"""A fast SAC torch Learner: one backward pass, per-gradient-step target updates, a device-side NaN guard,
and a fused update that samples its replay on the learner's device.

It is still an RLlib `Learner` (a subclass of `SACTorchLearner`): `LearnerGroup.update(batch=...)` or
`update(episodes=...)`, local or remote learners, checkpoints (`get_state`/`set_state`) and weight
sync to env runners all work as for the stock learner. What differs from `SACTorchLearner`:

* The actor, critic(s) and temperature losses (`losses.sac_losses`) are summed and back-propagated once
  (the stock learner calls `backward(retain_graph=True)` once per optimizer). Gradients are identical:
  each loss only reaches its own parameters.
* Target networks are Polyak-updated after *every gradient step* (every minibatch) with `config.tau`,
  like SB3, instead of once per `update()` call. `target_network_update_freq` is ignored (it counts env
  steps, which do not advance within one call). LR schedules still step once per call.
* NaN guard: one fused finite-check over all gradients per step; a non-finite step is skipped (no
  optimizer step, no target update) and counted in the `num_nonfinite_steps_skipped` metric. Use with
  `torch_skip_nan_gradients=True`, which turns off RLlib's per-parameter checks.
* The critic and twin critic share one Adam optimizer ("qf"); Adam runs fused (one kernel per step).
* log(alpha) is part of the learner state (stock RLlib 2.60 drops it from checkpoints).
* Loss: `weights` and `n_step` columns are optional (ones when absent), so a flat replay batch needs
  only obs, new_obs, actions, rewards, terminateds. The critic loss is RLlib's Huber loss by default
  or SB3's 0.5 * MSE with `learner_config_dict["gc_sac"]["critic_loss"] = "mse"`.

Two update paths, the same step:

* `update(batch=...)` (RLlib's): per minibatch `_uncompiled_update`, the finite check read on the host
  (the path before the fused update; `fused_update=False` trains through it).
* `update_from_replay(replay, num_steps, batch_size, timesteps)` (the fused one, `fused_update=True`):
  `num_steps` calls of `sac_step.SACStep` (N = 1; its noise from the seed's Philox stream, whose
  counters the learner checkpoints), each sampling its batch from `replay` (a buffer on
  this learner's device) inside the step and guarding non-finite gradients on the device. On CUDA the
  step is captured once into a CUDA graph and replayed (`cuda_graph`), optionally compiled first
  (`compile_update`); on a CPU it runs eagerly (or compiled). The loss statistics of the last step and
  the skip counter are read back once per call, and logged under the same keys as RLlib's path.

Knobs live in `config.learner_config_dict["gc_sac"]` (see `config.use_fast_learner`):
`critic_loss` ("huber" | "mse"), `torch_threads` (int or None), `fused_update`, `cuda_graph` and
`compile_update` (bools).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.algorithms.dqn.dqn_learner import DQNLearner
from ray.rllib.algorithms.sac.sac_learner import SACLearner
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.core import COMPONENT_OPTIMIZER, DEFAULT_MODULE_ID
from ray.rllib.core.learner.learner import Learner
from ray.rllib.core.learner.torch.torch_learner import TorchLearner
from ray.rllib.core.rl_module.apis import TargetNetworkAPI
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import (
    ALL_MODULES,
    MODULE_TRAIN_BATCH_SIZE_MEAN,
    NUM_ENV_STEPS_TRAINED,
    NUM_ENV_STEPS_TRAINED_LIFETIME,
    NUM_MODULE_STEPS_TRAINED,
    NUM_MODULE_STEPS_TRAINED_LIFETIME,
    NUM_TARGET_UPDATES,
    WEIGHTS_SEQ_NO,
)

from copilot_ray.algorithms.gc_sac.losses import CRITIC_LOSSES, sac_losses
from copilot_ray.algorithms.gc_sac.sac_step import FINITE, TOTAL_LOSS, SACStep, replay_step_call
from copilot_ray.torch_checks import all_finite

GC_SAC_KEY = "gc_sac"
NONFINITE_SKIPPED_KEY = "num_nonfinite_steps_skipped"
LOG_ALPHA_STATE_KEY = "gc_sac_log_alpha"
NOISE_STATE_KEY = "gc_sac_noise_stream"  # the fused step's noise counters: a resumed run draws on from them
BOOLEAN_KNOBS = ("fused_update", "cuda_graph", "compile_update")
SAC_OPTIMIZERS = ("qf", "policy", "alpha")  # the order of `SACStep`'s learning rates


def gc_sac_settings(config) -> dict[str, Any]:
    """The `learner_config_dict["gc_sac"]` settings of an AlgorithmConfig, with defaults, checked."""
    d = dict((getattr(config, "learner_config_dict", None) or {}).get(GC_SAC_KEY, {}))
    d.setdefault("critic_loss", "huber")
    d.setdefault("torch_threads", None)
    d.setdefault("fused_update", True)
    d.setdefault("cuda_graph", True)
    d.setdefault("compile_update", False)
    if d["critic_loss"] not in CRITIC_LOSSES:
        raise ValueError(
            f"learner_config_dict['gc_sac']['critic_loss'] must be 'huber' or 'mse', got {d['critic_loss']!r}"
        )
    for key in BOOLEAN_KNOBS:
        if not isinstance(d[key], bool):
            raise ValueError(f"learner_config_dict['gc_sac'][{key!r}] must be True or False, got {d[key]!r}")
    return d


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
        self._fused_steps: dict[str, SACStep] = {}
        self._replay_runs: dict[str, tuple[tuple, Any]] = {}
        self._skipped_read: dict[str, int] = {}
        self._noise_states: dict[str, dict[str, Any]] = {}  # restored before a module's step is built
        super().build()

    @property
    def device(self) -> torch.device:
        """Where this learner's module, optimizer state and (fused path) replay live."""
        return torch.device(self._device)

    # ------------------------------------------------------------------ optimizers
    @override(SACTorchLearner)
    def configure_optimizers_for_module(self, module_id, config=None) -> None:
        """Box actions: one Adam each for "qf" (both critics), "policy" and "alpha"; else SAC's own."""
        module = self._module[module_id]
        if not isinstance(module.action_space, gym.spaces.Box):
            return super().configure_optimizers_for_module(module_id, config)

        def adam(params):
            # Fused Adam: one kernel per step for all params, and the only Adam that skips a step on a
            # device-side flag (the fused update's NaN guard). capturable: steppable inside a CUDA graph.
            try:
                return torch.optim.Adam(params, eps=1e-7, fused=True, capturable=self.device.type == "cuda")
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
        self._forget_fused(module_id)

    # ------------------------------------------------------------------ loss
    @override(SACTorchLearner)
    def _compute_loss_for_module_continuous(self, *, module_id, config, batch, fwd_out):
        total, stats = sac_losses(
            fwd_out,
            batch,
            self.curr_log_alpha[module_id],
            self.target_entropy[module_id],
            gamma=config.gamma,
            critic_loss=self._gc_settings["critic_loss"],
            twin_q=config.twin_q,
        )
        self.metrics.log_dict(stats, key=module_id, window=1)
        return total

    # ------------------------------------------------------------------ RLlib's update path
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

    # ------------------------------------------------------------------ the fused update path
    def fused_step(self, module_id: str = DEFAULT_MODULE_ID) -> SACStep:
        """The module's `SACStep` for one seed (N = 1) over this learner's parameters and optimizers,
        which become views of the step's storage (built once; built again after anything that replaces
        optimizer state or modules). Its noise stream is keyed by the config's seed."""
        step = self._fused_steps.get(module_id)
        if step is None:
            config = self.config.get_config_for_module(module_id)
            if config.grad_clip is not None:
                raise ValueError(
                    f"grad_clip={config.grad_clip!r} is invalid with learner_config_dict['gc_sac']"
                    "['fused_update']=True (the fused step does not clip); use grad_clip=None or "
                    "fused_update=False"
                )
            step = SACStep(
                [self.module[module_id].unwrapped()],
                [self.curr_log_alpha[module_id]],
                [self._sac_optimizers(module_id)],
                self.target_entropy[module_id],
                gamma=config.gamma,
                tau=config.tau,
                critic_loss=self._gc_settings["critic_loss"],
                seeds=[int(self.config.seed or 0)],
            )
            if module_id in self._noise_states:
                step.noise.set_state(self._noise_states.pop(module_id))
            self._fused_steps[module_id] = step
            self._skipped_read[module_id] = 0
        return step

    def _sac_optimizers(self, module_id: str) -> list[torch.optim.Optimizer]:
        """The module's critics', actor's and temperature's optimizers, in that order."""
        named = dict(self.get_optimizers_for_module(module_id))
        return [named[name] for name in SAC_OPTIMIZERS]

    def _replay_run(self, module_id: str, replay: Any, batch_size: int):
        """The zero-argument step for `replay`, compiled and/or captured per the knobs; rebuilt when the
        replay's storage, the batch size or a learning rate changed (a graph holds all three fixed)."""
        lrs = tuple(float(self._get_optimizer_lr(o)) for o in self._sac_optimizers(module_id))
        key = (id(replay), replay.storage_version, int(batch_size), lrs)
        cached = self._replay_runs.get(module_id)
        if cached is not None and cached[0] == key:
            return cached[1]
        step = self.fused_step(module_id)
        step.set_learning_rates(dict(zip(SAC_OPTIMIZERS, lrs, strict=True)))
        run = replay_step_call(
            step,
            replay,
            batch_size,
            capture=self.device.type == "cuda" and self._gc_settings["cuda_graph"],
            compile_update=self._gc_settings["compile_update"],
        )
        self._replay_runs[module_id] = (key, run)
        return run

    def update_from_replay(
        self,
        replay: Any,
        num_steps: int,
        batch_size: int,
        timesteps: dict[str, Any] | None = None,
        *,
        module_id: str = DEFAULT_MODULE_ID,
    ) -> dict[str, Any]:
        """`num_steps` fused SAC steps on batches of `batch_size` sampled from `replay` on this
        learner's device (see the module docstring). Logs what `Learner.update` logs (the last step's
        losses, steps trained, target updates, learning rates, `num_nonfinite_steps_skipped`) and returns
        `self.metrics.reduce()`, as `update` does. `replay` must hold at least one transition."""
        self._check_is_built()
        if len(replay) == 0:
            raise ValueError("update_from_replay: the replay is empty; add transitions first")
        if replay.device != self.device:
            raise ValueError(
                f"update_from_replay: the replay is on {replay.device}, the learner on {self.device}"
            )
        run = self._replay_run(module_id, replay, batch_size)
        stats = {}
        for _ in range(int(num_steps)):
            stats = run()
        figures, skipped = self._read_fused_results(module_id, stats, int(num_steps))
        return self.record_steps(figures, skipped, num_steps, batch_size, timesteps, module_id=module_id)

    def _read_fused_results(
        self, module_id: str, stats: dict[str, torch.Tensor], steps: int
    ) -> tuple[dict[str, float], int]:
        """One device-to-host read of the last step's statistics and the skip counter: (the figures,
        the steps skipped since the last read)."""
        if steps == 0:
            return {}, 0
        names = [k for k in stats if k != FINITE]
        step = self._fused_steps[module_id]
        values = torch.stack([stats[k][0].float() for k in names] + [step.skipped[0].float()]).cpu().tolist()
        skipped_total = int(values.pop())
        skipped, self._skipped_read[module_id] = skipped_total - self._skipped_read[module_id], skipped_total
        return dict(zip(names, values, strict=True)), skipped

    def record_steps(
        self,
        figures: dict[str, float],
        skipped: int,
        steps: int,
        batch: int,
        timesteps: dict[str, Any] | None = None,
        *,
        module_id: str = DEFAULT_MODULE_ID,
    ) -> dict[str, Any]:
        """`steps` gradient steps of this learner's module, logged and reduced as `Learner.update` logs
        them, whoever ran them (its own `update_from_replay`, or a seed stack's stacked step, where the
        module's parameters are its row): `figures` the last step's loss statistics (host floats,
        `total_loss` among them), `skipped` how many of the steps were not finite (and so skipped)."""
        self._check_is_built()
        timesteps = timesteps or {}
        self.before_gradient_based_update(timesteps=timesteps)
        self._weights_seq_no += 1
        if steps:
            self._log_step_figures(module_id, figures, int(skipped), int(steps), int(batch))
        self.after_gradient_based_update(timesteps=timesteps)
        return self.metrics.reduce()

    def _log_step_figures(
        self, module_id: str, figures: dict[str, float], skipped: int, steps: int, batch: int
    ) -> None:
        self.metrics.log_dict({k: v for k, v in figures.items() if k != TOTAL_LOSS}, key=module_id, window=1)
        self.metrics.log_value((module_id, self.TOTAL_LOSS_KEY), figures[TOTAL_LOSS], window=1)
        self.metrics.log_value((module_id, NUM_TARGET_UPDATES), steps - skipped, reduce="lifetime_sum")
        if skipped:
            self.metrics.log_value((ALL_MODULES, NONFINITE_SKIPPED_KEY), skipped, reduce="lifetime_sum")
        trained = steps * batch
        self.metrics.log_value((module_id, WEIGHTS_SEQ_NO), self._weights_seq_no, window=1)
        self.metrics.log_value((module_id, MODULE_TRAIN_BATCH_SIZE_MEAN), batch, reduce="mean")
        for key in (module_id, ALL_MODULES):
            self.metrics.log_value((key, NUM_MODULE_STEPS_TRAINED), trained, reduce="sum")
            self.metrics.log_value((key, NUM_MODULE_STEPS_TRAINED_LIFETIME), trained, reduce="lifetime_sum")
        self.metrics.log_value((ALL_MODULES, NUM_ENV_STEPS_TRAINED), trained, reduce="sum")
        self.metrics.log_value((ALL_MODULES, NUM_ENV_STEPS_TRAINED_LIFETIME), trained, reduce="lifetime_sum")

    def _forget_fused(self, module_id: str | None = None) -> None:
        """Drops fused steps and their graphs (all, or one module's): their tensors may be stale. A
        dropped step's noise stream is kept for the next one (it draws on, not from the start)."""
        for mid in list(self._fused_steps) if module_id is None else [module_id]:
            if mid in self._fused_steps:
                self._noise_states[mid] = self._fused_steps[mid].noise.get_state()
        for cache in (self._fused_steps, self._replay_runs):
            if module_id is None:
                cache.clear()
            else:
                cache.pop(module_id, None)

    # ------------------------------------------------------------------ bookkeeping
    @override(DQNLearner)
    def after_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        """TorchLearner's lr-schedule stepping and logging, without DQNLearner's target update."""
        # Skip DQNLearner's once-per-call target update (targets move per gradient step above).
        TorchLearner.after_gradient_based_update(self, timesteps=timesteps)

    # Module set changes invalidate cached target-parameter lists and fused steps.
    @override(SACLearner)
    def add_module(self, **kwargs):
        """SACLearner's `add_module`, dropping the cached target-parameter lists and fused steps."""
        self._gc_target_pairs.clear()
        self._forget_fused()
        return super().add_module(**kwargs)

    @override(SACLearner)
    def remove_module(self, module_id, **kwargs):
        """SACLearner's `remove_module`, dropping the cached target-parameter lists and fused steps."""
        self._gc_target_pairs.clear()
        self._forget_fused()
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
            noise = dict(self._noise_states)
            noise.update({mid: step.noise.get_state() for mid, step in self._fused_steps.items()})
            state[NOISE_STATE_KEY] = noise
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
        self._forget_fused()
        if NOISE_STATE_KEY in state:
            self._noise_states = dict(state[NOISE_STATE_KEY])

    @override(TorchLearner)
    def _set_optimizer_state(self, state) -> None:
        """TorchLearner's, then each Adam made steppable inside a CUDA graph again on a GPU (a
        checkpoint written on a CPU says capturable=False)."""
        super()._set_optimizer_state(state)
        for optimizer in self._named_optimizers.values():
            for group in optimizer.param_groups:
                if group.get("fused"):
                    group["capturable"] = self.device.type == "cuda"
        self._forget_fused()
