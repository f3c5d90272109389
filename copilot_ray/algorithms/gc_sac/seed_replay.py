"""N seeds' replay buffers in one set of device tensors, sampled for all seeds at once.

Two kinds, as a one-seed trial has: flat transitions (`StackedTransitionBuffer`, CO-PILOT's and SAC's)
and HER's relabelling buffer (`StackedHindsightBuffer`, HER's and SoRB's).

`StackedTransitionBuffer(num_seeds, capacity, ...)` keeps each column as one [N, capacity, ...]
tensor and each seed's fill count in one [N] tensor. Seed i's buffer, `buffer.seeds[i]`, is a
`device_replay.DeviceTransitionBuffer` whose rows are row i of that storage: adding, its ring
arithmetic and checks, `transitions()` and its checkpoint format (`get_state`/`set_state`, the
one-seed `FlatTransitionBuffer` format) are that class's own. `sample(B, active=...)` draws B uniform rows
from each seed's own filled rows as one [N, B, ...] batch: one gather per column for all seeds and no
host sync, so it can sit inside `sac_step.SACStep`'s captured step. The uniforms are the seeds' own
sampling streams (`philox.PhiloxStreams`, the stream a one-seed buffer of that seed samples from; seed
i's buffer holds stream i, sharing its counter), so a seed's rows are the rows its one-seed buffer
draws, and a seed that is not `active` draws nothing.
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
from copilot_ray.algorithms.gc_sac.device_replay import SAMPLE_STREAM, DeviceTransitionBuffer, uniform_rows
from copilot_ray.algorithms.gc_sac.hindsight_buffer import GoalLayout
from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.replay_buffer import (
    ACTIONS,
    NEXT_OBS,
    OBS,
    REWARDS,
    TERMINATEDS,
    TRAIN_COLUMNS,
    TRUNCATEDS,
)


class _SeedRows(DeviceTransitionBuffer):
    """One seed's `DeviceTransitionBuffer` over its row of the stacked storage (never reallocated)."""

    def __init__(self, stack: StackedTransitionBuffer, seed: int):
        self._stack, self._seed = stack, seed
        super().__init__(stack.capacity, stack.device)
        self.sampler = stack.sampler.stream(seed)  # its checkpoint carries the stack's counter for it
        self._size_t = stack.sizes[seed]  # a 0-d view: this seed's fills write the stack's counts
        self._allocate(stack.obs_dim, stack.action_dim)

    def _allocate(self, obs_dim: int, action_dim: int) -> None:
        stack = self._stack
        if (self.capacity, int(obs_dim), int(action_dim)) != (
            stack.capacity,
            stack.obs_dim,
            stack.action_dim,
        ):
            raise ValueError(
                f"seed {self._seed}: a buffer of capacity {self.capacity}, obs_dim {obs_dim}, action_dim "
                f"{action_dim} does not fit the stack's (capacity {stack.capacity}, obs_dim {stack.obs_dim}, "
                f"action_dim {stack.action_dim})"
            )
        self._obs_dim, self._action_dim = int(obs_dim), int(action_dim)
        self._data = {k: v[self._seed] for k, v in stack.storage.items()}
        self.storage_version = stack.storage_version

    def set_state(self, state) -> None:
        """`DeviceTransitionBuffer.set_state`, refusing a snapshot of another capacity before touching
        anything (the stack's storage cannot grow for one seed)."""
        if int(state["capacity"]) != self._stack.capacity:
            raise ValueError(
                f"seed {self._seed}: a snapshot of capacity {state['capacity']} does not fit the stack's "
                f"capacity {self._stack.capacity}"
            )
        super().set_state(state)
        if self._data is None:  # an empty snapshot without dims: keep this seed's rows
            self._allocate(self._stack.obs_dim, self._stack.action_dim)


def gather_rows(column: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
    """column [N, capacity, ...] at rows [N, B] (each seed its own rows): [N, B, ...]."""
    n, b = rows.shape
    index = rows.view(n, b, *([1] * (column.dim() - 2))).expand(n, b, *column.shape[2:])
    return torch.gather(column, 1, index)


class StackedTransitionBuffer:
    """N seeds' FIFO rings of flat transitions on `device` (module docstring)."""

    def __init__(
        self,
        num_seeds: int,
        capacity: int,
        device: torch.device | str,
        obs_dim: int,
        action_dim: int,
        seeds: Iterable[int] | None = None,
    ):
        if int(num_seeds) < 1:
            raise ValueError(f"num_seeds must be >= 1, got {num_seeds}")
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self.num_seeds, self.capacity = int(num_seeds), int(capacity)
        self.device = torch.device(device)
        self.obs_dim, self.action_dim = int(obs_dim), int(action_dim)
        shape, dev = (self.num_seeds, self.capacity), self.device
        self.storage = {
            OBS: torch.zeros(*shape, self.obs_dim, device=dev),
            NEXT_OBS: torch.zeros(*shape, self.obs_dim, device=dev),
            ACTIONS: torch.zeros(*shape, self.action_dim, device=dev),
            REWARDS: torch.zeros(shape, device=dev),
            TERMINATEDS: torch.zeros(shape, dtype=torch.bool, device=dev),
            TRUNCATEDS: torch.zeros(shape, dtype=torch.bool, device=dev),
        }
        self.storage_version = 1  # allocated once: a captured step that reads it stays valid
        self.sizes = torch.zeros(self.num_seeds, dtype=torch.int64, device=dev)
        self.sampler = _sampler(self.num_seeds, seeds, dev)
        self.seeds = [_SeedRows(self, i) for i in range(self.num_seeds)]

    def __len__(self) -> int:
        """The smallest seed's fill (sampling needs every seed non-empty)."""
        return min(len(seed) for seed in self.seeds)

    def sample(
        self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS, active: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions of each seed's own, as [N, batch_size, ...] device tensors,
        with no host sync; only the `active` seeds' ([N] bool, default all) streams move. An empty seed's
        rows are its storage's first (zeros): it must not train on them."""
        rows = uniform_rows(self.sizes.unsqueeze(1), self.sampler, batch_size, active)
        return {key: gather_rows(self.storage[key], rows) for key in columns}


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
