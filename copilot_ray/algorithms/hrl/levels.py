"""The hierarchy's two SAC agents: one local `LearnerGroup` per level, each the fast goal-conditioned SAC
learner and module of `copilot_ray.algorithms.gc_sac` (the same as CO-PILOT's, SAC's and HER's), and an
`Actor` view of its policy for acting and for the off-policy correction's log-probabilities.

Local learner groups (no Ray actors): the trial runs its env loop on the driver, so both levels train in
its process; a flat batch goes straight to `LearnerGroup.update` via `gc_sac.update_from_buffer`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.models.base import ENCODER_OUT

from copilot_ray.algorithms.gc_sac import use_fast_learner
from copilot_ray.algorithms.hrl.config import HRLConfig

_SAC_TRAINING = (
    "actor_lr",
    "critic_lr",
    "alpha_lr",
    "gamma",
    "initial_alpha",
    "target_entropy",
    "tau",
    "train_batch_size_per_learner",
)


def build_learner_group(cfg: HRLConfig, level: str, observation_space: gym.Space, action_space: gym.Space):
    """A local GC-SAC LearnerGroup for `level` ("low" / "high") with that level's settings."""
    settings = dict(getattr(cfg, level))
    sac = (
        SACConfig()
        .environment(observation_space=observation_space, action_space=action_space)
        .training(**{k: settings[k] for k in _SAC_TRAINING})
        .debugging(seed=cfg.seed)
    )
    use_fast_learner(sac, hidden=settings["hidden"], torch_threads=cfg.torch_threads)
    return sac.build_learner_group()


class Actor:
    """A level's squashed-Gaussian policy read straight off its learner's module (no train/eval mode
    switches per call): tanh of the mean, a sample, or log pi(a | obs)."""

    def __init__(self, learner_group, chunk: int = 32768):
        if not learner_group.is_local:
            raise ValueError("Actor needs a local LearnerGroup (num_learners=0)")
        self.module = learner_group._learner.module[DEFAULT_MODULE_ID]  # the module being trained
        self.dist_cls = self.module.get_train_action_dist_cls()
        self.chunk = int(chunk)

    def _logits(self, obs: np.ndarray) -> torch.Tensor:
        x = torch.as_tensor(np.ascontiguousarray(obs), dtype=torch.float32)
        return self.module.pi(self.module.pi_encoder({"obs": x})[ENCODER_OUT])

    @torch.no_grad()
    def act(self, obs: np.ndarray, generator: torch.Generator | None = None) -> np.ndarray:
        """Actions in [-1, 1] for flat inputs [n, D]: tanh(mean), or with a `generator` tanh of a
        Gaussian sample drawn from it."""
        mean, log_std = self._logits(obs).chunk(2, dim=-1)
        if generator is not None:
            mean = mean + torch.randn(mean.shape, generator=generator) * torch.exp(log_std)
        return torch.tanh(mean).numpy()

    @torch.no_grad()
    def log_prob(self, obs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """log pi(a | obs) [n] of actions in [-1, 1] (the squashed Gaussian's, actions at +-1 clamped),
        in chunks so that a large correction batch does not hold every hidden activation at once."""
        out = np.empty(len(obs), np.float32)
        for i in range(0, len(obs), self.chunk):
            logits = self._logits(obs[i : i + self.chunk])
            a = torch.as_tensor(np.ascontiguousarray(actions[i : i + self.chunk]), dtype=torch.float32)
            out[i : i + self.chunk] = self.dist_cls.from_logits(logits).logp(a).numpy()
        return out


def learner_stats(results: list[dict[str, Any]]) -> dict[str, float]:
    """qf_loss and alpha of the last learner call's results ({} when there was none)."""
    if not results:
        return {}
    last = results[-1][DEFAULT_MODULE_ID]

    def value(key: str) -> float:
        v = last[key]
        v = v.peek() if hasattr(v, "peek") else v
        return float(v.item() if hasattr(v, "item") else v)

    return {"qf_loss": value("qf_loss"), "alpha": value("alpha_value")}
