"""Driving a (GC-)SAC `LearnerGroup` from a replay buffer with one call per iteration."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from copilot_ray.algorithms.gc_sac.replay_buffer import TRAIN_COLUMNS

# n -> n sampled transitions as the learner's columns (obs, new_obs, actions, rewards, terminateds), numpy
Sampler = Callable[[int], dict[str, np.ndarray]]


def host_sampler(buffer) -> Sampler:
    """`Sampler` of a one-seed torch replay buffer (`FlatTransitionBuffer`, `HindsightReplayBuffer`): its
    seed's rows on the host (a view of CPU storage, a copy from another device)."""
    return lambda n: {k: v[0].cpu().numpy() for k, v in buffer.sample(int(n), TRAIN_COLUMNS).items()}


def make_train_batch(
    columns: dict[str, np.ndarray],
    *,
    module_id: str = DEFAULT_MODULE_ID,
    with_weights_and_n_step: bool = False,
) -> MultiAgentBatch:
    """Wraps flat transition columns into the `MultiAgentBatch` a Learner takes via `update(batch=...)`.

    A ready batch skips the learner connector. `GCSACTorchLearner` needs only obs, new_obs, actions,
    rewards, terminateds; RLlib's stock `SACTorchLearner` also reads `weights` and `n_step` columns:
    pass `with_weights_and_n_step=True` for it (columns of ones).
    """
    cols = dict(columns)
    n = len(cols[TRAIN_COLUMNS[0]])
    if with_weights_and_n_step:
        cols.setdefault("weights", np.ones(n, dtype=np.float32))
        cols.setdefault("n_step", np.ones(n, dtype=np.float32))
    return MultiAgentBatch({module_id: SampleBatch(cols)}, env_steps=n)


def update_from_buffer(
    learner_group,
    sample: Sampler,
    num_gradient_steps: int,
    batch_size: int,
    timesteps: dict[str, Any] | int | None = None,
    *,
    module_id: str = DEFAULT_MODULE_ID,
    with_weights_and_n_step: bool = False,
    steps_per_call: int = 16,
) -> list[dict[str, Any]]:
    """`num_gradient_steps` SAC gradient steps of `batch_size` samples each from `sample`.

    Every `steps_per_call` gradient steps are one learner call: sample `steps_per_call * batch_size`
    transitions at once (`host_sampler(buffer)` for a replay buffer) and `learner_group.update(batch=...,
    minibatch_size=batch_size, num_epochs=1, shuffle_batch_per_epoch=False, timesteps=...)`, which runs
    one gradient step per minibatch.
    Why chunks: RLlib's minibatch iterator slices the whole batch for every minibatch, so the cost
    per step grows with the batch (measured: 118 updates/s at 16 steps per call, 32 at 256, 11 at 1024).
    `timesteps` is RLlib's timesteps dict (an int is taken as `num_env_steps_sampled_lifetime`); it
    drives lr schedules. Returns the learner group's results of every call (one dict per learner and call,
    as `LearnerGroup.update` returns), or [] when nothing was done.
    """
    n = int(num_gradient_steps)
    if n <= 0:
        return []
    if isinstance(timesteps, int | np.integer):
        timesteps = {NUM_ENV_STEPS_SAMPLED_LIFETIME: int(timesteps)}
    results: list[dict[str, Any]] = []
    for start in range(0, n, int(steps_per_call)):
        k = min(int(steps_per_call), n - start)
        cols = sample(k * int(batch_size))
        batch = make_train_batch(cols, module_id=module_id, with_weights_and_n_step=with_weights_and_n_step)
        results += learner_group.update(
            batch=batch,
            minibatch_size=int(batch_size),
            num_epochs=1,
            shuffle_batch_per_epoch=False,
            timesteps=timesteps or {},
        )
    return results


class GradientStepSchedule:
    """Turns an update-to-data ratio into integer gradient steps per iteration, keeping the fraction.

    `steps = schedule.on_env_steps(new_env_steps)` returns round-down(ratio * steps + carry) and carries
    the remainder, so the long-run ratio is exact (ratio 0.25 with 1 new step per call gives one
    gradient step every fourth call). `learning_starts` env steps must be collected first (steps
    before that earn no updates, like SB3's `learning_starts`).
    """

    def __init__(self, updates_per_env_step: float = 1.0, learning_starts: int = 0):
        if updates_per_env_step < 0:
            raise ValueError(f"updates_per_env_step must be >= 0, got {updates_per_env_step}")
        self.updates_per_env_step = float(updates_per_env_step)
        self.learning_starts = int(learning_starts)
        self._env_steps = 0
        self._carry = 0.0

    def on_env_steps(self, new_env_steps: int) -> int:
        """Counts `new_env_steps` sampled env steps; returns the gradient steps they earn."""
        before = self._env_steps
        self._env_steps += int(new_env_steps)
        eligible = max(0, self._env_steps - max(before, self.learning_starts))
        credit = self._carry + self.updates_per_env_step * eligible
        steps = int(np.floor(credit + 1e-9))
        self._carry = credit - steps
        return steps

    def get_state(self) -> dict[str, Any]:
        """A picklable snapshot: ratio, learning_starts, env steps seen and the carried fraction."""
        return {
            "updates_per_env_step": self.updates_per_env_step,
            "learning_starts": self.learning_starts,
            "env_steps": self._env_steps,
            "carry": self._carry,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restores a `get_state` snapshot."""
        self.updates_per_env_step = float(state["updates_per_env_step"])
        self.learning_starts = int(state["learning_starts"])
        self._env_steps = int(state["env_steps"])
        self._carry = float(state["carry"])
