"""How CO-PILOT's agent phase turns sampled sub-task episodes into SAC gradient steps.

Three interchangeable paths (config `fast_learner`, and the fast learner's `fused_update` knob):
- `FusedLearnerUpdater` (default): the replay lives on the learner's device (`FlatTransitionBuffer`,
  or HER's `HindsightReplayBuffer`) and each call is `learner.update_from_replay`: every gradient step
  samples its batch there and runs as one fused step with no host sync (a CUDA graph replay on a GPU).
- `FastLearnerUpdater` (`fused_update=False`): the same replay on the host + SB3-shaped SAC learner,
  many gradient steps per `learner_group.update(batch=...)` call (copilot_ray.algorithms.gc_sac). About
  10x faster than the stock path on CPU.
- `StockLearnerUpdater`: RLlib's own episode replay buffer and learner connector, one gradient step per
  call, exactly as RLlib's SAC does it; kept for comparison.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np
from ray.rllib.utils.from_config import from_config
from ray.rllib.utils.metrics import ALL_MODULES, TD_ERROR_KEY
from ray.rllib.utils.numpy import convert_to_numpy
from ray.rllib.utils.replay_buffers import ReplayBuffer
from ray.rllib.utils.replay_buffers.utils import update_priorities_in_episode_replay_buffer

from copilot_ray.algorithms.gc_sac import gc_sac_settings, host_sampler, update_from_buffer


class StockLearnerUpdater:
    """RLlib's SAC update path: its (prioritised) episode replay buffer, learner connector and
    one `learner_group.update(episodes=...)` per gradient step, with priority updates."""

    def __init__(self, config, learner_group, replay_buffer=None):
        self.config = config
        self.learner_group = learner_group
        self.replay_buffer = replay_buffer if replay_buffer is not None else make_rllib_replay_buffer(config)

    def add(self, episodes) -> None:
        self.replay_buffer.add(episodes)

    def update(self, num_updates: int, timesteps: dict[str, int]) -> list[dict[str, Any]]:
        cfg = self.config
        results: list[dict[str, Any]] = []
        for _ in range(num_updates):
            episodes = self.replay_buffer.sample(
                num_items=cfg.total_train_batch_size,
                n_step=cfg.n_step,
                gamma=cfg.gamma,
                beta=cfg.replay_buffer_config.get("beta"),
                sample_episodes=True,
            )
            learner_results = self.learner_group.update(episodes=episodes, timesteps=timesteps)
            td_errors = defaultdict(list)
            for res in learner_results:
                for module_id, module_results in res.items():
                    if module_id != ALL_MODULES and TD_ERROR_KEY in module_results:
                        td_errors[module_id].extend(convert_to_numpy(module_results.pop(TD_ERROR_KEY).peek()))
            update_priorities_in_episode_replay_buffer(
                replay_buffer=self.replay_buffer,
                td_errors={m: {TD_ERROR_KEY: np.concatenate(e)} for m, e in td_errors.items()},
            )
            results.extend(learner_results)
        return results

    def get_state(self) -> dict[str, Any]:
        # RLlib checkpoints its own buffer when `store_buffer_in_checkpoints=True`.
        return {}

    def set_state(self, state: dict[str, Any]) -> None:
        """Nothing of ours to restore (see get_state)."""


def make_rllib_replay_buffer(config):
    """The episode replay buffer RLlib's Algorithm.setup builds from `config.replay_buffer_config`."""
    buffer_config = dict(config.replay_buffer_config)
    if "EpisodeReplayBuffer" in str(buffer_config.get("type", "")):
        buffer_config["metrics_num_episodes_for_smoothing"] = config.metrics_num_episodes_for_smoothing
    return from_config(ReplayBuffer, buffer_config)


class ReplayUpdater:
    """What both fast paths share: the agent's ring `ring` of a torch replay buffer (`add_episodes`,
    `sample(n)`, `get_state` / `set_state` per seed; `GoalSAC.device_replay`). 0 alone; seed i of a seed
    stack, whose buffer and updates are the stack's (`stacked_updates.StackedAgentUpdates`), so it never
    calls `update`. Sampling reads no global generator: the ring's state holds its stream's counter."""

    def __init__(self, config, learner_group, buffer, ring: int = 0):
        self.config = config
        self.learner_group = learner_group
        self.buffer = buffer
        self.ring = int(ring)

    def add(self, episodes) -> None:
        self.buffer.add_episodes(episodes, seed=self.ring)

    def _steps(self, num_updates: int) -> bool:
        """Whether `num_updates` gradient steps are owed and can be sampled."""
        if self.buffer.num_seeds != 1:
            raise RuntimeError("a stacked seed's agent is updated by its stack, not alone")
        return num_updates > 0 and len(self.buffer) > 0

    def replay_size(self) -> int:
        """Transitions in this agent's ring of the replay."""
        return self.buffer.size_of(self.ring)

    def replay_states(self, n: int, rng: np.random.Generator):
        """n replayed (observations, achieved goals) of a hindsight buffer (SoRB's graph)."""
        return self.buffer.sample_states(n, rng, seed=self.ring)

    def get_state(self) -> dict[str, Any]:
        return {"buffer": self.buffer.get_state(seed=self.ring)}

    def set_state(self, state: dict[str, Any]) -> None:
        self.buffer.set_state(state["buffer"], seed=self.ring)


class FastLearnerUpdater(ReplayUpdater):
    """`fused_update=False`: the replay sampled on the host, N gradient steps in one
    `learner_group.update(batch=...)` call (the learners may be remote)."""

    def update(self, num_updates: int, timesteps: dict[str, int]) -> list[dict[str, Any]]:
        if not self._steps(num_updates):
            return []
        batch_size = self.config.train_batch_size_per_learner
        return update_from_buffer(
            self.learner_group, host_sampler(self.buffer), num_updates, batch_size, timesteps
        )


class FusedLearnerUpdater(ReplayUpdater):
    """The replay on the learner's device, sampled inside each fused gradient step
    (`GCSACTorchLearner.update_from_replay`). Needs the learner in this process (`num_learners=0`, as
    every algorithm here runs): the buffer is handed to it, not shipped."""

    def __init__(self, config, learner_group, buffer, ring: int = 0):
        super().__init__(config, learner_group, buffer, ring)
        self.learner = local_learner(config, learner_group)

    def update(self, num_updates: int, timesteps: dict[str, int]) -> list[dict[str, Any]]:
        """As `LearnerGroup.update` returns: one result dict per learner (here one), [] for no step."""
        if not self._steps(num_updates):
            return []
        batch_size = self.config.train_batch_size_per_learner
        return [self.learner.update_from_replay(self.buffer, num_updates, batch_size, timesteps)]


def local_learner(config, learner_group):
    """The learner of a local learner group: the fused update hands it the replay in this process."""
    if not learner_group.is_local:
        raise ValueError(
            f"num_learners={config.num_learners!r} is invalid with learner_config_dict['gc_sac']"
            "['fused_update']=True: the fused update samples its replay on the learner in this "
            "process; use num_learners=0 or fused_update=False"
        )
    return learner_group._learner


def fused_update(config) -> bool:
    """Whether the fast learner trains through the fused update (`FusedLearnerUpdater`)."""
    return bool(config.fast_learner and gc_sac_settings(config)["fused_update"])


def replay_capacity(config) -> int:
    """Transitions the agent's replay buffer keeps (RLlib's `replay_buffer_config["capacity"]`)."""
    return int(config.replay_buffer_config.get("capacity", 1_000_000))
