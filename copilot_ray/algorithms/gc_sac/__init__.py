"""Fast goal-conditioned SAC on RLlib's new API stack (SB3-speed updates, still an RLlib Learner).

Pieces:
  * `GCSACCatalog` / `GCSACTorchRLModule`: SB3-shaped actor and twin critics (critic = MLP on
    concat(obs, action)).
  * `GCSACTorchLearner`: one backward pass, per-gradient-step target updates, NaN guard; its fused
    update (`SACStep` at N = 1: the whole step on the device, no host sync, a CUDA graph on a GPU)
    samples a replay buffer that lives on the learner's device.
  * `SACStep`: the SAC step of N seeds at once over the RLModule's own networks (N = 1: one seed);
    `PhiloxStreams`: per-seed counter-based random streams on the device (its noise).
  * `sac_losses` / `bellman_target`: SAC's losses, shared by both update paths.
  * `FlatTransitionBuffer`: ring buffers of flat transitions fed from RLlib episodes, torch tensors on
    the learner's device sampled there: a ring per seed ([N, capacity, ...]; N = 1 for one seed) and
    one sampler on the seeds' streams.
  * `HindsightReplayBuffer`: HER as a replay buffer (SB3's way), the same layout: goals relabelled when
    sampled, on the device (inside the fused step).
  * `update_from_buffer`: N gradient steps in one `learner_group.update(batch=...)` call, from a host
    sampler (`host_sampler(buffer)`: a one-seed buffer's rows on the host).
  * `GradientStepSchedule`: update-to-data ratio -> integer gradient steps per iteration.
  * `use_fast_learner(config)`: switch a SACConfig to all of the above.
"""

from copilot_ray.algorithms.gc_sac.catalog import (
    SB3_MODEL_CONFIG,
    ConcatObsActionMLPEncoder,
    ConcatObsActionMLPEncoderConfig,
    GCSACCatalog,
    GCSACTorchRLModule,
    count_parameters,
)
from copilot_ray.algorithms.gc_sac.config import use_fast_learner, uses_fast_learner
from copilot_ray.algorithms.gc_sac.hindsight_buffer import GoalLayout, HindsightReplayBuffer, TorchRewardFn
from copilot_ray.algorithms.gc_sac.learner import (
    GC_SAC_KEY,
    NONFINITE_SKIPPED_KEY,
    GCSACTorchLearner,
    gc_sac_settings,
)
from copilot_ray.algorithms.gc_sac.losses import bellman_target, sac_losses
from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.replay_buffer import COLUMNS, TRAIN_COLUMNS, FlatTransitionBuffer
from copilot_ray.algorithms.gc_sac.sac_step import SACStep
from copilot_ray.algorithms.gc_sac.updater import (
    GradientStepSchedule,
    host_sampler,
    make_train_batch,
    update_from_buffer,
)

__all__ = [
    "COLUMNS",
    "GC_SAC_KEY",
    "NONFINITE_SKIPPED_KEY",
    "SB3_MODEL_CONFIG",
    "TorchRewardFn",
    "TRAIN_COLUMNS",
    "ConcatObsActionMLPEncoder",
    "ConcatObsActionMLPEncoderConfig",
    "FlatTransitionBuffer",
    "GCSACCatalog",
    "GCSACTorchLearner",
    "GCSACTorchRLModule",
    "GoalLayout",
    "HindsightReplayBuffer",
    "PhiloxStreams",
    "SACStep",
    "GradientStepSchedule",
    "bellman_target",
    "count_parameters",
    "gc_sac_settings",
    "host_sampler",
    "sac_losses",
    "uses_fast_learner",
    "make_train_batch",
    "update_from_buffer",
    "use_fast_learner",
]
