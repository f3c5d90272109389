"""HER's relabelling buffer with its rows on the learner's device, relabelled and sampled there.

`DeviceHindsightBuffer` is a `HindsightReplayBuffer` (same episodes in, same state out: either restores
the other's checkpoint) whose columns are torch tensors on `device`. `sample(batch_size)` does
everything the numpy buffer's does, on the device and without a host synchronisation, so it can run
inside the fused SAC step and its CUDA graph: uniform rows (`device_replay.uniform_rows`), hindsight
goals for the first her_ratio of them (`future`, `final` or `episode`), their rewards and terminations
from a torch `reward_fn`, the dense reward added back, the agent's flat inputs composed for the new
goals. Rows and goals are drawn from the buffer's sampler, the seed's Philox stream
(`device_replay.SAMPLE_STREAM`), in that order each call.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np
import torch

from copilot_ray.algorithms.gc_sac.device_replay import SAMPLE_STREAM, gather_rows, uniform_rows
from copilot_ray.algorithms.gc_sac.hindsight_buffer import (
    STORED_COLUMNS,
    GoalLayout,
    HindsightReplayBuffer,
    overwritten_prefix,
)
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

# (next achieved goals [n, g], goals [n, g], collisions bool [n]) -> (rewards [n], terminateds bool [n]),
# torch tensors on the buffer's device, no host synchronisation.
TorchRewardFn = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]
TORCH_DTYPES = {np.float32: torch.float32, bool: torch.bool, np.int64: torch.int64}


def hindsight_storage(
    rows: tuple[int, ...], layout: GoalLayout, action_dim: int, device: torch.device
) -> dict[str, torch.Tensor]:
    """Zeroed device columns of HER's stored layout (`STORED_COLUMNS`), each `rows` deep: (capacity,)
    for one buffer, (seeds, capacity) for a stack."""
    widths = {"obs": layout.obs_dim, "goal": layout.goal_dim, "action": action_dim}
    return {
        name: torch.zeros(rows if w is None else (*rows, widths[w]), dtype=TORCH_DTYPES[dtype], device=device)
        for name, (w, dtype) in STORED_COLUMNS.items()
    }


class DeviceHindsightBuffer(HindsightReplayBuffer):
    """A `HindsightReplayBuffer` on `device` (module docstring) with a ring per seed: its stored columns
    are [N, capacity, ...] tensors (N = 1 by default); `reward_fn` is a `TorchRewardFn`.

    The numpy buffer's adding, checks and checkpoint format are used per ring: `add_episodes(...,
    seed=i)`, `get_state(seed=i)` and `set_state(state, seed=i)` run them on seed i's ring (its host
    counters and its row of the storage); `sample(B)` relabels [N, B] rows for every seed at once.
    `seeds` (one per ring) key the rings' sampling streams; a one-seed buffer takes `seed`."""

    def __init__(
        self,
        capacity: int,
        layout: GoalLayout,
        reward_fn: TorchRewardFn,
        n_sampled_goal: int = 4,
        goal_selection: str = "future",
        device: torch.device | str = "cpu",
        seed: int = 0,
        seeds: Iterable[int] | None = None,
    ):
        self.seeds = [int(seed)] if seeds is None else [int(s) for s in seeds]
        if not self.seeds:
            raise ValueError("a DeviceHindsightBuffer needs at least one seed")
        self.num_seeds = len(self.seeds)
        self._rings = [[0, 0, 0] for _ in self.seeds]  # each ring's (next row, fill, lifetime adds)
        self._ring = 0  # the ring the numpy buffer's methods work on (`_on_ring`)
        self._storage: dict[str, torch.Tensor] | None = None
        super().__init__(capacity, layout, reward_fn, n_sampled_goal, goal_selection)
        self.device = torch.device(device)
        self.sampler = PhiloxStreams(self.seeds, SAMPLE_STREAM, self.device)
        self.sizes = torch.zeros(self.num_seeds, dtype=torch.int64, device=self.device)
        self.pointers = torch.zeros(self.num_seeds, dtype=torch.int64, device=self.device)  # for "episode"
        self.storage_version = 0

    # --------------------------------------------------- the numpy buffer's counters, of the current ring
    _ptr = property(lambda self: self._rings[self._ring][0], lambda self, v: self._set_ring(0, v))
    _size = property(lambda self: self._rings[self._ring][1], lambda self, v: self._set_ring(1, v))
    _num_added = property(lambda self: self._rings[self._ring][2], lambda self, v: self._set_ring(2, v))

    def _set_ring(self, what: int, value: int) -> None:
        self._rings[self._ring][what] = int(value)

    @property
    def _data(self) -> dict[str, torch.Tensor] | None:
        """The current ring's row of the storage (what the numpy buffer's methods read and write)."""
        if self._storage is None:
            return None
        return {k: v[self._ring] for k, v in self._storage.items()}

    @_data.setter
    def _data(self, value) -> None:
        # The numpy buffer drops its rows before a restore; here they stay (the ring's fill is reset).
        if value is not None:
            raise AttributeError("a DeviceHindsightBuffer's storage is allocated by _allocate")

    @contextlib.contextmanager
    def _on_ring(self, seed: int):
        """The numpy buffer's methods applied to ring `seed` while inside; then the device's copies of
        its fill and write pointer."""
        if not 0 <= int(seed) < self.num_seeds:
            raise ValueError(f"seed index {seed} is not one of this buffer's {self.num_seeds} rings")
        before, self._ring = self._ring, int(seed)
        try:
            yield
        finally:
            self.sizes[self._ring].fill_(self._size)
            self.pointers[self._ring].fill_(self._ptr)
            self._ring = before

    # ------------------------------------------------------------------------- storage on the device
    def _allocate(self, action_dim: int) -> None:
        if self._storage is not None and int(action_dim) == self._action_dim:
            return  # every ring shares the storage
        if self._storage is not None and self.num_seeds > 1:
            raise ValueError(
                f"seed {self.seeds[self._ring]}: action size {action_dim} does not fit the stack's "
                f"{self._action_dim}"
            )
        self._action_dim = int(action_dim)
        self._storage = hindsight_storage(
            (self.num_seeds, self.capacity), self.layout, self._action_dim, self.device
        )
        self.storage_version += 1

    def _write_rows(self, rows: np.ndarray, cols: Mapping[str, np.ndarray]) -> None:
        index = torch.as_tensor(np.asarray(rows, np.int64), device=self.device)
        for name, values in cols.items():
            column = self._data[name]
            column.index_copy_(
                0, index, torch.as_tensor(np.ascontiguousarray(values)).to(self.device, column.dtype)
            )

    def _filled(self) -> dict[str, np.ndarray]:
        return {k: v[: self._size].cpu().numpy().copy() for k, v in self._data.items()}

    def _rows_as_numpy(self, name: str, rows: np.ndarray) -> np.ndarray:
        return self._data[name].index_select(0, torch.as_tensor(rows, device=self.device)).cpu().numpy()

    # ------------------------------------------------------------------------- one seed's ring
    def add_episode(self, *args, seed: int | None = None, **kwargs) -> int:
        """`HindsightReplayBuffer.add_episode` into ring `seed` (default: the current ring, 0)."""
        with self._on_ring(self._ring if seed is None else seed):
            return super().add_episode(*args, **kwargs)

    def add_episodes(self, episodes, seed: int = 0) -> int:
        """`HindsightReplayBuffer.add_episodes` into ring `seed`."""
        with self._on_ring(seed):
            return super().add_episodes(episodes)

    def __len__(self) -> int:
        """The smallest ring's fill (a sample needs every seed it trains non-empty)."""
        return min(ring[1] for ring in self._rings)

    def size_of(self, seed: int) -> int:
        """Ring `seed`'s fill."""
        return self._rings[seed][1]

    @property
    def num_added(self) -> int:
        """Transitions added over the buffer's lifetime, all rings together."""
        return sum(ring[2] for ring in self._rings)

    def sample_states(self, n: int, rng: np.random.Generator, seed: int = 0):
        """`HindsightReplayBuffer.sample_states` of ring `seed` (SoRB's graph over replayed states)."""
        with self._on_ring(seed):
            return super().sample_states(n, rng)

    def get_state(self, seed: int = 0) -> dict[str, Any]:
        """Ring `seed` in `HindsightReplayBuffer.get_state`'s format, plus its sampler's counter."""
        with self._on_ring(seed):
            return {**super().get_state(), "sampler": self.sampler.stream(seed).get_state()}

    def set_state(self, state: Mapping[str, object], seed: int = 0) -> None:
        """`HindsightReplayBuffer.set_state` (either buffer's one-seed state) into ring `seed`, and its
        sampler's counter where the snapshot has one. Another capacity is refused first (by the numpy
        buffer), and so is another action size in a stack."""
        action_dim = state["action_dim"]
        if self.num_seeds > 1 and action_dim is not None and self._action_dim not in (None, int(action_dim)):
            raise ValueError(
                f"seed {self.seeds[seed]}: a snapshot of action size {action_dim} does not fit the "
                f"stack's {self._action_dim}"
            )
        with self._on_ring(seed):
            super().set_state(state)
        if state.get("sampler") is not None:
            self.sampler.stream(seed).set_state(state["sampler"])

    def write_pointers(self) -> torch.Tensor:
        """Each ring's next row, [N, 1] on the device (against [N, B] sampled rows; a captured step
        reads it as the buffer fills)."""
        return self.pointers.unsqueeze(1)

    # ------------------------------------------------------------------------------------ sampling
    def sample(
        self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS, active: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions of each seed's own, the first her_ratio of them with
        hindsight goals, as the agent's flat columns: [N, batch_size, ...] device tensors, no host sync.
        Rows, then goals, from each seed's stream; only the `active` seeds' ([N] bool) streams move. An
        empty ring's rows are its storage's first: it must not train on them."""
        if self._storage is None:
            raise ValueError("cannot sample from an empty DeviceHindsightBuffer")
        rows = uniform_rows(self.sizes.unsqueeze(1), self.sampler, int(batch_size), active)

        def goal_uniforms(shape: torch.Size) -> torch.Tensor:
            return self.sampler.uniform(shape[-1], active, dtype=torch.float64)

        def take(name: str, at: torch.Tensor) -> torch.Tensor:
            return gather_rows(self._storage[name], at)

        return relabelled_columns(self, rows, take, columns, goal_uniforms)


def relabelled_columns(
    buffer: Any,
    rows: torch.Tensor,
    take: Callable[[str, torch.Tensor], torch.Tensor],
    columns: Iterable[str],
    uniform: Callable[[torch.Size], torch.Tensor],
) -> dict[str, torch.Tensor]:
    """The agent's flat columns for storage rows `rows` ([..., B]: a batch, or a batch per seed), the
    first her_ratio of each batch with hindsight goals; `take(name, rows)` gathers a stored column at
    rows of that shape. `buffer` gives her_ratio, goal_selection, reward_fn, layout and capacity (a
    `DeviceHindsightBuffer`). `uniform(shape)`:
    the float64 uniforms that pick hindsight goals, one per row of `shape` (the buffer's sampler)."""
    axis = rows.dim() - 1  # the batch axis of rows; a column's rows carry its width after it
    goals, rewards, terminateds = take("goal", rows), take(REWARDS, rows), take(TERMINATEDS, rows)
    n_her = int(round(buffer.her_ratio * rows.shape[axis]))
    if n_her:
        her = rows.narrow(axis, 0, n_her)
        new_goals = _hindsight_goals(buffer, her, take, uniform)
        width = new_goals.shape[-1]
        r, t = buffer.reward_fn(
            take("next_achieved", her).reshape(-1, width),
            new_goals.reshape(-1, width),
            take("collision", her).reshape(-1),
        )
        rest = rows.shape[axis] - n_her
        goals = torch.cat([new_goals, goals.narrow(axis, n_her, rest)], dim=axis)
        relabelled = (r.reshape(her.shape) + take("dense", her)).to(torch.float32)
        rewards = torch.cat([relabelled, rewards.narrow(axis, n_her, rest)], dim=axis)
        terminateds = torch.cat(
            [t.reshape(her.shape).to(torch.bool), terminateds.narrow(axis, n_her, rest)], dim=axis
        )
    out = {
        OBS: _compose(buffer, take("observation", rows), goals, take("achieved", rows)),
        NEXT_OBS: _compose(buffer, take("next_observation", rows), goals, take("next_achieved", rows)),
        ACTIONS: take(ACTIONS, rows),
        REWARDS: rewards,
        TERMINATEDS: terminateds,
        TRUNCATEDS: torch.zeros(rows.shape, dtype=torch.bool, device=rows.device),
    }
    return {k: out[k] for k in columns}


def _hindsight_goals(buffer: Any, rows: torch.Tensor, take, uniform) -> torch.Tensor:
    """A next achieved goal of each row's own episode: its last (final), one from its step on (future)
    or one from anywhere in it (episode)."""
    start, length, step = (take(k, rows) for k in ("episode_start", "episode_length", "step"))
    if buffer.goal_selection == "final":
        offset = length - 1
    else:  # from its step on (future), or from anywhere in it that is still its own (episode)
        low = (
            step
            if buffer.goal_selection == "future"
            else overwritten_prefix(buffer.write_pointers(), start, length, buffer.capacity)
        )
        u = uniform(rows.shape)
        offset = torch.minimum(low + (u * (length - low)).long(), length - 1)  # uniform in [low, length)
    return take("next_achieved", (start + offset) % buffer.capacity)


def _compose(buffer: Any, observation, goal, achieved) -> torch.Tensor:
    parts = [observation, goal, goal - achieved] if buffer.layout.with_delta else [observation, goal]
    return torch.cat(parts, dim=-1)
