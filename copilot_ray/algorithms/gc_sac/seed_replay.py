"""HER's relabelling buffer for N seeds in one set of device tensors, sampled for all seeds at once.

(The flat kind is `device_replay.DeviceTransitionBuffer` itself, with its leading seed axis.)
`StackedHindsightBuffer(num_seeds, capacity, ...)` keeps each stored column as one [N, capacity, ...]
tensor and each seed's fill and write pointer in [N] tensors. Seed i's episodes are added, and its
checkpoint read and written (the one-seed `HindsightReplayBuffer` format), by a
`device_hindsight.DeviceHindsightBuffer` over row i of that storage (`add_episodes(..., seed=i)`,
`get_state(seed=i)`). `sample(B, active=...)` draws B rows of each seed's own and relabels them as the
one-seed buffer does, as one [N, B, ...] batch with no host sync, so it can sit inside
`sac_step.SACStep`'s captured step. Rows and goals come from the seeds' own sampling streams
(`philox.PhiloxStreams`, the streams a one-seed buffer of that seed samples from), so a seed's batch is
the batch its one-seed buffer draws, and a seed that is not `active` draws nothing.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch

from copilot_ray.algorithms.gc_sac.device_hindsight import (
    DeviceHindsightBuffer,
    TorchRewardFn,
    hindsight_storage,
    relabelled_columns,
)
from copilot_ray.algorithms.gc_sac.device_replay import SAMPLE_STREAM, gather_rows, uniform_rows
from copilot_ray.algorithms.gc_sac.hindsight_buffer import GoalLayout
from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.replay_buffer import (
    TRAIN_COLUMNS,
)


class _SeedEpisodes(DeviceHindsightBuffer):
    """One seed's `DeviceHindsightBuffer` over its row of the stacked storage (never reallocated)."""

    def __init__(self, stack: StackedHindsightBuffer, seed: int):
        self._stack, self._seed = stack, seed
        super().__init__(
            stack.capacity,
            stack.layout,
            stack.reward_fn,
            stack.n_sampled_goal,
            stack.goal_selection,
            stack.device,
        )
        self.sampler = stack.sampler.stream(seed)
        self._size_t = stack.sizes[seed]  # a 0-d view: this seed's adds write the stack's counts
        self._ptr_t = stack.pointers[seed]  # (and its ring's next row)
        self._allocate(stack.action_dim)

    def _allocate(self, action_dim: int) -> None:
        if int(action_dim) != self._stack.action_dim:
            raise ValueError(
                f"seed {self._seed}: action size {action_dim} does not fit the stack's {self._stack.action_dim}"
            )
        self._action_dim = int(action_dim)
        self._data = {k: v[self._seed] for k, v in self._stack.storage.items()}
        self.storage_version = self._stack.storage_version

    def set_state(self, state) -> None:
        """`DeviceHindsightBuffer.set_state` (which refuses another capacity before changing anything);
        another action size is refused first too; an empty snapshot without one keeps this seed's rows."""
        if state["action_dim"] is not None and int(state["action_dim"]) != self._stack.action_dim:
            raise ValueError(
                f"seed {self._seed}: a snapshot of action size {state['action_dim']} does not fit the "
                f"stack's {self._stack.action_dim}"
            )
        super().set_state(state)
        if self._data is None:
            self._allocate(self._stack.action_dim)


class StackedHindsightBuffer:
    """N seeds' HER buffers (`DeviceHindsightBuffer`, one per row of [N, capacity, ...] storage:
    `seeds[i]` adds seed i's episodes and checkpoints in the one-seed format); `sample(B)` gives every
    seed B of its own transitions, the first her_ratio of them relabelled, as [N, B, ...] columns,
    with no host sync (`device_hindsight.relabelled_columns`, the one-seed buffer's own relabelling)."""

    def __init__(
        self,
        num_seeds: int,
        capacity: int,
        layout: GoalLayout,
        reward_fn: TorchRewardFn,
        action_dim: int,
        n_sampled_goal: int = 4,
        goal_selection: str = "future",
        device: torch.device | str = "cpu",
        seeds: Iterable[int] | None = None,
    ):
        if int(num_seeds) < 1:
            raise ValueError(f"num_seeds must be >= 1, got {num_seeds}")
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self.num_seeds, self.capacity, self.action_dim = int(num_seeds), int(capacity), int(action_dim)
        self.layout, self.reward_fn = layout, reward_fn
        self.n_sampled_goal, self.goal_selection = int(n_sampled_goal), goal_selection
        self.device = torch.device(device)
        self.storage = hindsight_storage(
            (self.num_seeds, self.capacity), layout, self.action_dim, self.device
        )
        self.storage_version = 1
        self.sizes = torch.zeros(self.num_seeds, dtype=torch.int64, device=self.device)
        self.pointers = torch.zeros(self.num_seeds, dtype=torch.int64, device=self.device)
        self.sampler = _sampler(self.num_seeds, seeds, self.device)
        # Each seed's buffer checks capacity, n_sampled_goal and goal_selection as the one-seed one does.
        self.seeds = [_SeedEpisodes(self, i) for i in range(self.num_seeds)]
        self.her_ratio = self.seeds[0].her_ratio

    def __len__(self) -> int:
        """The smallest seed's fill (sampling needs every seed non-empty)."""
        return min(len(seed) for seed in self.seeds)

    def add_episodes(self, episodes, seed: int = 0) -> int:
        """Seed `seed`'s episodes into its rings (its row's `DeviceHindsightBuffer`)."""
        return self.seeds[seed].add_episodes(episodes)

    def size_of(self, seed: int) -> int:
        """Seed `seed`'s fill."""
        return len(self.seeds[seed])

    def get_state(self, seed: int = 0):
        """Seed `seed`'s buffer in the one-seed format (its sampler's counter included)."""
        return self.seeds[seed].get_state()

    def set_state(self, state, seed: int = 0) -> None:
        """Restores a one-seed snapshot into seed `seed`'s rows."""
        self.seeds[seed].set_state(state)

    def write_pointers(self) -> torch.Tensor:
        """Each seed's ring's next row, [N, 1] (against [N, B] sampled rows)."""
        return self.pointers.unsqueeze(1)

    def sample(
        self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS, active: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """`batch_size` transitions of each seed's own, relabelled as one seed's buffer relabels (rows,
        then hindsight goals, from each seed's own stream), as [N, batch_size, ...] device tensors; only
        the `active` seeds' streams move. An empty seed's rows are its storage's first."""
        rows = uniform_rows(self.sizes.unsqueeze(1), self.sampler, batch_size, active)

        def goal_uniforms(shape: torch.Size) -> torch.Tensor:
            return self.sampler.uniform(shape[-1], active, dtype=torch.float64)

        def take(name: str, at: torch.Tensor) -> torch.Tensor:
            return gather_rows(self.storage[name], at)

        return relabelled_columns(self, rows, take, columns, goal_uniforms)


def _sampler(num_seeds: int, seeds: Iterable[int] | None, device: torch.device) -> PhiloxStreams:
    """The stack's sampling streams: one per seed (`seeds`, default 0 ... N - 1)."""
    seeds = list(range(num_seeds)) if seeds is None else [int(s) for s in seeds]
    if len(seeds) != num_seeds:
        raise ValueError(f"need one seed per row ({num_seeds}), got {len(seeds)}")
    return PhiloxStreams(seeds, SAMPLE_STREAM, device)
