"""`use_fast_learner`: switch any `SACConfig` (or subclass) to the fast goal-conditioned SAC path."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from copilot_ray.algorithms.gc_sac.catalog import GCSACCatalog, GCSACTorchRLModule
from copilot_ray.algorithms.gc_sac.learner import GC_SAC_KEY, GCSACTorchLearner, gc_sac_settings


def use_fast_learner(
    config: SACConfig,
    *,
    hidden: Sequence[int] = (256, 256),
    activation: str = "relu",
    torch_threads: int | None = 2,
    updates_per_env_step: float = 1.0,
    critic_loss: str = "huber",
    fused_update: bool = True,
    cuda_graph: bool = True,
    compile_update: bool = False,
) -> SACConfig:
    """Configures `config` (in place, and returns it) for the fast GC-SAC module and learner.

    Sets:
      * the RLModule: `GCSACTorchRLModule` built by `GCSACCatalog` (SB3-shaped: actor MLP `hidden` ->
        linear mean/log-std head; twin critics = MLP `hidden` on concat(obs, action) -> linear; target
        critics), `model_config` fcnet_hiddens=hidden, fcnet_activation=activation,
        head_fcnet_hiddens=[]; other model_config keys are kept;
      * the learner class `GCSACTorchLearner` (one backward pass, per-gradient-step Polyak targets with
        `config.tau`, fused NaN guard);
      * `torch_skip_nan_gradients=True` (RLlib's per-parameter NaN checks off; the learner guards
        NaNs itself);
      * `learner_config_dict["gc_sac"] = {torch_threads, updates_per_env_step, critic_loss,
        fused_update, cuda_graph, compile_update}`.

    Args:
        config: Any SACConfig (e.g. CO-PILOT's config subclass). Not calling this keeps RLlib's stock
            SAC module and learner.
        hidden: Hidden layer sizes of the actor and of each critic.
        activation: Hidden activation ("relu" as in SB3).
        torch_threads: `torch.set_num_threads` on each learner (None: leave torch's default). Two
            threads are ~1.5x faster than one for 256x256 nets at batch 256.
        updates_per_env_step: The update-to-data ratio: gradient steps per newly sampled env step.
            The training loop reads it back (`gc_sac_settings(config)["updates_per_env_step"]`) and
            asks `GradientStepSchedule(ratio).on_env_steps(n)` how many steps to run; the learner
            itself does not use it.
        critic_loss: "huber" (RLlib's SAC default) or "mse" (SB3's 0.5 * squared error).
        fused_update: train through `GCSACTorchLearner.update_from_replay` (the whole step on the
            learner's device, the replay sampled there, no host sync inside; GoalSAC's default), or,
            False, through RLlib's `update(batch=...)` fed from the same replay sampled on the host.
        cuda_graph: on a CUDA learner, capture the fused step in one CUDA graph and replay it.
        compile_update: `torch.compile` the fused step (before the capture on a GPU).
    """
    if not isinstance(config, SACConfig):
        raise TypeError(f"use_fast_learner needs a SACConfig (or subclass), got {type(config).__name__}")
    if config.framework_str != "torch":
        raise ValueError(f"use_fast_learner supports framework='torch' only, got {config.framework_str!r}")
    hidden = [int(h) for h in hidden]
    if not hidden or any(h <= 0 for h in hidden):
        raise ValueError(f"hidden must be a non-empty sequence of positive ints, got {hidden}")
    if updates_per_env_step < 0:
        raise ValueError(f"updates_per_env_step must be >= 0, got {updates_per_env_step}")

    model_config = config._model_config
    if dataclasses.is_dataclass(model_config):
        model_config = dataclasses.asdict(model_config)
    model_config = dict(model_config or {})
    model_config.update(
        fcnet_hiddens=hidden,
        fcnet_activation=activation,
        head_fcnet_hiddens=[],
        head_fcnet_activation=activation,
    )
    config.rl_module(
        rl_module_spec=RLModuleSpec(module_class=GCSACTorchRLModule, catalog_class=GCSACCatalog),
        model_config=model_config,
    )

    learner_config_dict: dict[str, Any] = dict(config.learner_config_dict or {})
    learner_config_dict[GC_SAC_KEY] = {
        "torch_threads": torch_threads,
        "updates_per_env_step": float(updates_per_env_step),
        "critic_loss": critic_loss,
        "fused_update": fused_update,
        "cuda_graph": cuda_graph,
        "compile_update": compile_update,
    }
    config.learners(learner_class=GCSACTorchLearner, learner_config_dict=learner_config_dict)
    config.framework(torch_skip_nan_gradients=True)
    gc_sac_settings(config)  # validates
    return config


def uses_fast_learner(config: SACConfig) -> bool:
    """Whether `use_fast_learner` was applied to `config`."""
    return GC_SAC_KEY in (config.learner_config_dict or {})
