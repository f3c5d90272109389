"""`FlatTransitionBuffer`'s twin whose rows live in torch tensors on the learner's device, one ring per
seed: each column is one [N, capacity, ...] tensor (N = 1 for a one-seed run, N seeds for a stack).

Sampling happens on that device with no host synchronisation, so it can sit inside the fused SAC step
and its CUDA graph: row indices are `floor(u * size)` for uniform `u` from the buffer's sampler, the
seed's Philox stream (`philox.PhiloxStreams`, purpose `SAMPLE_STREAM`: the same rows on every device,
and the same rows for a seed whether its buffer is alone or a row of a stack), where `size` is a 0-d
device tensor updated in place when rows are added. The storage is
allocated once at full capacity (on the first `add`), so its address never moves while a graph reads
it; `storage_version` counts (re)allocations, and a captured step is rebuilt when it changes.

`sample(B)` draws B rows of each seed's own as one [N, B, ...] batch (one gather per column for all
seeds). Adding is one host-to-device copy per column per call, to one seed's ring (`seed=i`); each
seed's state (`get_state(seed=i)`) has `FlatTransitionBuffer`'s format, numpy arrays included, plus the
seed's sampler counter, so a seed's checkpoint restores into either buffer, or a one-seed run's.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import torch

from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.replay_buffer import (
    ACTIONS,
    NEXT_OBS,
    OBS,
    REWARDS,
    TERMINATEDS,
    TRAIN_COLUMNS,
    TRUNCATEDS,
    FlatTransitionBuffer,
    ring_advance,
    ring_segments,
)

# The purpose word of the replay's row-sampling streams (a seed's noise streams have another).
SAMPLE_STREAM = 2


def uniform_rows(
    size: torch.Tensor, sampler: PhiloxStreams, batch_size: int, active: torch.Tensor | None = None
) -> torch.Tensor:
    """[N, batch_size] uniform row indices, row i in [0, size_i) from stream i of `sampler`, for an int64
    device tensor `size` (0-d for one stream, or [N, 1]), without reading `size` on the host (float64
    uniforms keep the rounding below one row). An empty buffer's rows are 0 (its batch is not trained
    on); `active` ([N] bool): the streams that move (the others' rows are drawn but not consumed)."""
    u = sampler.uniform(int(batch_size), active, dtype=torch.float64)
    return torch.minimum((u * size).long(), (size - 1).clamp(min=0))


def gather_rows(column: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
    """column [N, capacity, ...] at rows [N, B] (each seed its own rows): [N, B, ...]."""
    n, b = rows.shape
    index = rows.view(n, b, *([1] * (column.dim() - 2))).expand(n, b, *column.shape[2:])
    return torch.gather(column, 1, index)


class DeviceTransitionBuffer(FlatTransitionBuffer):
    """N seeds' FIFO rings of flat transitions (a `FlatTransitionBuffer`'s adds and checks per ring)
    whose rows are torch tensors on `device` (module docstring).

    Args:
        capacity: transitions kept per seed; a seed's oldest are overwritten first.
        device: where the rows live and are sampled (the learner's device).
        obs_dim, action_dim: flat sizes; inferred from the first `add` when None.
        seed: keys the sampler's stream of a one-seed buffer (the run's seed).
        seeds: one per ring, for N seeds (instead of `seed`).
    """

    def __init__(
        self,
        capacity: int,
        device: torch.device | str = "cpu",
        obs_dim: int | None = None,
        action_dim: int | None = None,
        seed: int = 0,
        seeds: Iterable[int] | None = None,
    ):
        self.device = torch.device(device)
        self.seeds = [int(seed)] if seeds is None else [int(s) for s in seeds]
        if not self.seeds:
            raise ValueError("a DeviceTransitionBuffer needs at least one seed")
        self.num_seeds = len(self.seeds)
        self.sampler = PhiloxStreams(self.seeds, SAMPLE_STREAM, self.device)
        self.sizes = torch.zeros(self.num_seeds, dtype=torch.int64, device=self.device)  # what sampling reads
        self.storage_version = 0
        super().__init__(capacity, obs_dim, action_dim)
        n = self.num_seeds  # each ring's host counters (the base class's, one per seed)
        self._ptr, self._size, self._num_added = [0] * n, [0] * n, [0] * n

    def _allocate(self, obs_dim: int, action_dim: int) -> None:
        rows, dev = (self.num_seeds, self.capacity), self.device
        self._obs_dim, self._action_dim = obs_dim, action_dim
        self._data = {
            OBS: torch.zeros((*rows, obs_dim), dtype=torch.float32, device=dev),
            NEXT_OBS: torch.zeros((*rows, obs_dim), dtype=torch.float32, device=dev),
            ACTIONS: torch.zeros((*rows, action_dim), dtype=torch.float32, device=dev),
            REWARDS: torch.zeros(rows, dtype=torch.float32, device=dev),
            TERMINATEDS: torch.zeros(rows, dtype=torch.bool, device=dev),
            TRUNCATEDS: torch.zeros(rows, dtype=torch.bool, device=dev),
        }
        self.storage_version += 1

    # ---------------------------------------------------------------- adding
    def add(self, transitions: Mapping[str, Any], seed: int = 0) -> int:
        """`FlatTransitionBuffer.add` into seed `seed`'s ring (its index in `seeds`), then the device's
        copy of its size (what sampling reads)."""
        cols = self._checked_columns(transitions)
        if cols is None:
            return 0
        n = len(cols[OBS])
        for start, rows in ring_segments(self._ptr[seed], n, self.capacity):
            for key, values in cols.items():
                target = self._data[key][seed, start : start + (rows.stop - rows.start)]
                source = np.ascontiguousarray(values[rows])
                target.copy_(torch.from_numpy(source).to(target.dtype), non_blocking=False)
        self._ptr[seed], self._size[seed] = ring_advance(self._ptr[seed], self._size[seed], n, self.capacity)
        self._num_added[seed] += n
        self.sizes[seed].fill_(self._size[seed])
        return n

    def add_episodes(self, episodes: Iterable[Any], seed: int = 0) -> int:
        """Adds RLlib `SingleAgentEpisode`s to seed `seed`'s ring; returns rows added."""
        transitions = self.episodes_to_transitions(episodes)
        return self.add(transitions, seed) if transitions else 0

    def __len__(self) -> int:
        """The smallest seed's fill (a sample needs every seed it trains non-empty)."""
        return min(self._size)

    def size_of(self, seed: int) -> int:
        """Seed `seed`'s fill."""
        return self._size[seed]

    @property
    def num_added(self) -> int:
        """Transitions added over the buffer's lifetime, all seeds together."""
        return sum(self._num_added)

    # Pickled as plain attributes (tensors included), not through the numpy buffer's snapshot.
    __getstate__ = object.__getstate__

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    # ---------------------------------------------------------------- sampling
    def sample(
        self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS, active: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions (with replacement) of each seed's own, [N, batch_size, ...]
        device tensors, no host sync; only the `active` seeds' ([N] bool, default all) streams move. An
        empty seed's rows are its storage's first (zeros): it must not train on them."""
        rows = uniform_rows(self.sizes.unsqueeze(1), self.sampler, int(batch_size), active)
        return {k: gather_rows(self._data[k], rows) for k in columns}

    # ---------------------------------------------------------------- state
    def transitions(self, seed: int = 0) -> dict[str, np.ndarray]:
        """Seed `seed`'s stored transitions, oldest first (numpy copies)."""
        size, ptr = self._size[seed], self._ptr[seed]
        if self._data is None or size == 0:
            return {}
        if size < self.capacity:
            order = torch.arange(size, device=self.device)
        else:
            order = (torch.arange(self.capacity, device=self.device) + ptr) % self.capacity
        return {k: v[seed].index_select(0, order).cpu().numpy() for k, v in self._data.items()}

    def get_state(self, seed: int = 0) -> dict[str, Any]:
        """Seed `seed`'s ring in `FlatTransitionBuffer.get_state`'s format (filled rows in storage order
        as numpy, the write pointer and the counters) and its sampler's counter."""
        filled = None
        if self._data is not None and self._size[seed] > 0:
            filled = {k: v[seed, : self._size[seed]].cpu().numpy().copy() for k, v in self._data.items()}
        return {
            "capacity": self.capacity,
            "obs_dtype": np.dtype(np.float32).str,
            "obs_dim": self._obs_dim,
            "action_dim": self._action_dim,
            "num_added": self._num_added[seed],
            "ptr": self._ptr[seed],
            "size": self._size[seed],
            "data": filled,
            "sampler": self.sampler.stream(seed).get_state(),
        }

    def set_state(self, state: Mapping[str, Any], seed: int = 0) -> None:
        """Restores a one-seed snapshot of either buffer into seed `seed`'s ring (its rows, write pointer
        and counters, and its sampler's counter where the snapshot has one: a numpy buffer's has none).
        A one-seed buffer takes another capacity (its storage is reallocated); a stack refuses it, and
        other sizes, before changing anything."""
        capacity, dims = int(state["capacity"]), (state["obs_dim"], state["action_dim"])
        if self.num_seeds > 1 and (
            capacity != self.capacity or (dims[0] is not None and dims != (self._obs_dim, self._action_dim))
        ):
            raise ValueError(
                f"seed {self.seeds[seed]}: a snapshot of capacity {capacity}, obs_dim {dims[0]}, action_dim "
                f"{dims[1]} does not fit the stack's (capacity {self.capacity}, obs_dim {self._obs_dim}, "
                f"action_dim {self._action_dim})"
            )
        if state.get("sampler") is not None:
            self.sampler.stream(seed).set_state(state["sampler"])
        if self.num_seeds == 1 and (capacity != self.capacity or dims != (self._obs_dim, self._action_dim)):
            self.capacity, self._data = capacity, None
            if dims[0] is not None and dims[1] is not None:
                self._allocate(int(dims[0]), int(dims[1]))
        self._ptr[seed], self._size[seed] = 0, 0
        self._num_added[seed] = int(state["num_added"])
        if state.get("data"):
            size = int(state["size"])
            if self._data is None:
                self._allocate(int(dims[0]), int(dims[1]))
            for key, values in state["data"].items():
                if key in self._data:
                    target = self._data[key][seed, :size]
                    target.copy_(torch.as_tensor(np.asarray(values)[:size]).to(target.dtype))
            self._size[seed], self._ptr[seed] = size, int(state["ptr"])
        self.sizes[seed].fill_(self._size[seed])
