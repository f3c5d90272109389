"""An SB3-shaped SAC catalog and RLModule for goal-conditioned SAC.

RLlib's default SAC module encodes observations and actions with separate MLPs and fuses them with a
third one (about 1.4 M trainable parameters for 256x256 nets on a 4-d observation). Stable-Baselines3's
SAC, which this project matches for speed, uses

    actor:   obs -> MLP[256, 256] (relu) -> Linear -> (mean, log_std)
    critics: concat(obs, action) -> MLP[256, 256] (relu) -> Linear -> Q      (twin, plus targets)

which is about 0.34 M parameters for the point maze (obs dim 4 = position + goal, action dim 2),
counting the actor, both critics and both target critics. `GCSACCatalog` builds exactly that out of
RLlib's own building blocks, so that `DefaultSACTorchRLModule` (and its inference-only version on the
env runners) keeps working unchanged. `GCSACTorchRLModule` only replaces the training forward pass with
a leaner one (same maths, fewer autograd nodes).

The observation space must be a flat 1-d `Box` (the CO-PILOT env wrapper concatenates the observation
and the current sub-goal).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.algorithms.sac.sac_catalog import SACCatalog
from ray.rllib.algorithms.sac.sac_learner import ACTION_DIST_INPUTS_NEXT, QF_PREDS, QF_TWIN_PREDS
from ray.rllib.algorithms.sac.torch.default_sac_torch_rl_module import DefaultSACTorchRLModule
from ray.rllib.core.columns import Columns
from ray.rllib.core.models.base import ENCODER_OUT, Encoder
from ray.rllib.core.models.configs import MLPEncoderConfig
from ray.rllib.core.models.torch.encoder import TorchMLPEncoder
from ray.rllib.core.rl_module.rl_module import RLModule
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule
from ray.rllib.utils.annotations import override

# Model-config settings that make RLlib's catalog build SB3-shaped networks.
SB3_MODEL_CONFIG: dict[str, Any] = {
    "fcnet_hiddens": [256, 256],
    "fcnet_activation": "relu",
    "head_fcnet_hiddens": [],
    "head_fcnet_activation": "relu",
    "free_log_std": False,
}


class ConcatObsActionMLPEncoder(TorchMLPEncoder):
    """A plain MLP on concat(obs, action): the Q-function encoder of SB3's `ContinuousCritic`."""

    @override(TorchMLPEncoder)
    def _forward(self, inputs: dict, **kwargs) -> dict:
        x = torch.cat([inputs[Columns.OBS], inputs[Columns.ACTIONS]], dim=-1)
        return {ENCODER_OUT: self.net(x)}


class ConcatObsActionMLPEncoderConfig(MLPEncoderConfig):
    """`MLPEncoderConfig` whose encoder reads concat(obs, action); `input_dims` = (obs_dim + act_dim,)."""

    @override(MLPEncoderConfig)
    def build(self, framework: str = "torch") -> Encoder:
        """Builds the torch `ConcatObsActionMLPEncoder` (torch only)."""
        if framework != "torch":
            raise ValueError(f"GCSACCatalog supports framework='torch' only, got {framework!r}")
        self._validate(framework)
        return ConcatObsActionMLPEncoder(self)


class GCSACCatalog(SACCatalog):
    """SACCatalog whose (continuous-action) Q encoders are plain MLPs on concat(obs, action).

    The actor is the base catalog's MLP encoder (`fcnet_hiddens`, `fcnet_activation`) plus a linear
    mean/log-std head (`head_fcnet_hiddens=[]`); see `SB3_MODEL_CONFIG` for the matching model config.
    """

    @override(SACCatalog)
    def _build_qf_encoder_continuous(self, framework: str) -> Encoder:
        obs_space, act_space = self.observation_space, self.action_space
        if not (isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) == 1):
            raise ValueError(
                "GCSACCatalog needs a flat 1-d Box observation space (concatenate observation and "
                f"goal in the env wrapper); got observation_space={obs_space}"
            )
        hiddens = list(self._model_config_dict["fcnet_hiddens"])
        if not hiddens:
            raise ValueError("GCSACCatalog needs at least one hidden layer in model_config['fcnet_hiddens']")
        activation = self._model_config_dict["fcnet_activation"]
        # The same initializers as RLlib's fcnet stack, for the hidden layers and the output layer alike.
        init = {
            "weights_initializer": self._model_config_dict.get("fcnet_kernel_initializer"),
            "weights_initializer_config": self._model_config_dict.get("fcnet_kernel_initializer_kwargs"),
            "bias_initializer": self._model_config_dict.get("fcnet_bias_initializer"),
            "bias_initializer_config": self._model_config_dict.get("fcnet_bias_initializer_kwargs"),
        }
        self.qf_encoder_config = ConcatObsActionMLPEncoderConfig(
            input_dims=[int(obs_space.shape[0]) + int(act_space.shape[0])],
            hidden_layer_dims=hiddens[:-1],
            hidden_layer_activation=activation,
            output_layer_dim=hiddens[-1],
            output_layer_activation=activation,
            **{
                f"{layer}_layer_{key}": value for layer in ("hidden", "output") for key, value in init.items()
            },
        )
        return self.qf_encoder_config.build(framework=framework)


class GCSACTorchRLModule(DefaultSACTorchRLModule):
    """`DefaultSACTorchRLModule` with `GCSACCatalog` and a leaner continuous training forward pass.

    Outputs the same keys as the stock module (so `SACTorchLearner` can consume them too):
    `QF_PREDS`, `QF_TWIN_PREDS`, `action_dist_inputs`, `action_dist_inputs_next`, `logp_resampled`,
    `q_curr` (min twin Q at fresh actions, gradients to the actor only), `logp_next_resampled` and
    `q_target_next` (min twin target Q at next obs and fresh next actions, no gradients).
    Differences from the stock pass, none of which changes a gradient: the next-state actor pass and
    the target critics run under `torch.no_grad()`.
    """

    @override(DefaultSACTorchRLModule)
    def __init__(self, *args, **kwargs):
        if kwargs.get("catalog_class") is None:
            kwargs["catalog_class"] = GCSACCatalog
        super().__init__(*args, **kwargs)

    @override(TorchRLModule)
    def forward_train(self, batch: dict[str, Any], **kwargs) -> dict[str, Any]:
        """RLModule's training forward pass, switching to train mode only when not already in it."""
        # TorchRLModule.forward_train calls `self.train()` on every step, which walks all submodules
        # (~0.5 ms per gradient step); only switch modes when needed.
        if not self.training:
            self.train()
        return RLModule.forward_train(self, batch, **kwargs)

    @override(DefaultSACTorchRLModule)
    def _forward_train_continuous(self, batch: dict[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        obs, next_obs, actions = batch[Columns.OBS], batch[Columns.NEXT_OBS], batch[Columns.ACTIONS]
        dist_cls = self.get_train_action_dist_cls()

        # Critics at the replayed actions (gradients to the critics).
        q_in = {Columns.OBS: obs, Columns.ACTIONS: actions}
        out[QF_PREDS] = self._qf_forward_train_helper(q_in, self.qf_encoder, self.qf)
        if self.twin_q:
            out[QF_TWIN_PREDS] = self._qf_forward_train_helper(q_in, self.qf_twin_encoder, self.qf_twin)

        # Actor at the current obs, reparameterised (gradients to the actor).
        logits = self.pi(self.pi_encoder({Columns.OBS: obs})[ENCODER_OUT])
        out[Columns.ACTION_DIST_INPUTS] = logits
        actions_new, out["logp_resampled"] = dist_cls.from_logits(logits).rsample_and_logp()

        # Min twin Q at the fresh actions: gradients flow to the actions (actor) but not the critics.
        critic_params = self._critic_params()
        for p in critic_params:
            p.requires_grad_(False)
        try:
            out["q_curr"] = self.compute_q_values({Columns.OBS: obs, Columns.ACTIONS: actions_new})
        finally:
            for p in critic_params:
                p.requires_grad_(True)

        # Bellman-target ingredients: no gradients at all.
        with torch.no_grad():
            logits_next = self.pi(self.pi_encoder({Columns.OBS: next_obs})[ENCODER_OUT])
            out[ACTION_DIST_INPUTS_NEXT] = logits_next
            actions_next, out["logp_next_resampled"] = dist_cls.from_logits(logits_next).sample_and_logp()
            out["q_target_next"] = self.forward_target({Columns.OBS: next_obs, Columns.ACTIONS: actions_next})
        return out

    def _critic_params(self) -> list[torch.nn.Parameter]:
        cached = getattr(self, "_gc_critic_params", None)
        if cached is None:
            nets = [self.qf_encoder, self.qf]
            if self.twin_q:
                nets += [self.qf_twin_encoder, self.qf_twin]
            cached = [p for net in nets for p in net.parameters()]
            # Plain attribute, not a registered submodule/buffer (a list is ignored by nn.Module).
            object.__setattr__(self, "_gc_critic_params", cached)
        return cached


def count_parameters(module: torch.nn.Module) -> dict[str, int]:
    """Trainable / non-trainable (target) parameter counts of an RLModule."""
    trainable = sum(p.numel() for p in module.parameters() if p.requires_grad)
    frozen = sum(p.numel() for p in module.parameters() if not p.requires_grad)
    return {"trainable": trainable, "target": frozen, "total": trainable + frozen}
