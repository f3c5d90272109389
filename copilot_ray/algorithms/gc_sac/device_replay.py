"""`FlatTransitionBuffer`'s twin whose rows live in torch tensors on the learner's device.

Sampling happens on that device with no host synchronisation, so it can sit inside the fused SAC step
and its CUDA graph: row indices are `floor(u * size)` for uniform `u` from the buffer's sampler, the
seed's Philox stream (`philox.PhiloxStreams`, purpose `SAMPLE_STREAM`: the same rows on every device,
and the same rows for a seed whether its buffer is alone or a row of a stack), where `size` is a 0-d
device tensor updated in place when rows are added. The storage is
allocated once at full capacity (on the first `add`), so its address never moves while a graph reads
it; `storage_version` counts (re)allocations, and a captured step is rebuilt when it changes.

Adding is one host-to-device copy per column per call. The state (`get_state`) has
`FlatTransitionBuffer`'s format, numpy arrays included, plus the sampler's counter, so either buffer
restores the other's checkpoint.
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


class DeviceTransitionBuffer(FlatTransitionBuffer):
    """A `FlatTransitionBuffer` (its adds, checks and ring) whose rows are torch tensors on `device`
    (module docstring).

    Args:
        capacity: transitions kept; the oldest are overwritten first.
        device: where the rows live and are sampled (the learner's device).
        obs_dim, action_dim: flat sizes; inferred from the first `add` when None.
        seed: keys the sampler's stream (the run's seed).
    """

    def __init__(
        self,
        capacity: int,
        device: torch.device | str = "cpu",
        obs_dim: int | None = None,
        action_dim: int | None = None,
        seed: int = 0,
    ):
        self.device = torch.device(device)
        self.sampler = PhiloxStreams([int(seed)], SAMPLE_STREAM, self.device)
        self._size_t = torch.zeros((), dtype=torch.int64, device=self.device)
        self.storage_version = 0
        super().__init__(capacity, obs_dim, action_dim)

    def _allocate(self, obs_dim: int, action_dim: int) -> None:
        c, dev = self.capacity, self.device
        self._obs_dim, self._action_dim = obs_dim, action_dim
        self._data = {
            OBS: torch.zeros((c, obs_dim), dtype=torch.float32, device=dev),
            NEXT_OBS: torch.zeros((c, obs_dim), dtype=torch.float32, device=dev),
            ACTIONS: torch.zeros((c, action_dim), dtype=torch.float32, device=dev),
            REWARDS: torch.zeros((c,), dtype=torch.float32, device=dev),
            TERMINATEDS: torch.zeros((c,), dtype=torch.bool, device=dev),
            TRUNCATEDS: torch.zeros((c,), dtype=torch.bool, device=dev),
        }
        self.storage_version += 1

    def _write(self, start: int, cols: Mapping[str, np.ndarray]) -> None:
        for key, values in cols.items():
            target = self._data[key][start : start + len(values)]
            target.copy_(torch.from_numpy(np.ascontiguousarray(values)).to(target.dtype), non_blocking=False)

    def add(self, transitions: Mapping[str, Any]) -> int:
        """`FlatTransitionBuffer.add`, then the device's copy of the size (what sampling reads)."""
        added = super().add(transitions)
        self._size_t.fill_(self._size)
        return added

    # Pickled as plain attributes (tensors included), not through the numpy buffer's snapshot.
    __getstate__ = object.__getstate__

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    # ---------------------------------------------------------------- sampling
    def sample(self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions (with replacement) as device tensors, no host sync. The
        caller makes sure the buffer is not empty (`len(buffer) > 0`, a host-side count)."""
        rows = uniform_rows(self._size_t, self.sampler, int(batch_size))[0]
        return {k: self._data[k].index_select(0, rows) for k in columns}

    # ---------------------------------------------------------------- state
    def transitions(self) -> dict[str, np.ndarray]:
        """All stored transitions, oldest first (numpy copies)."""
        if self._data is None or self._size == 0:
            return {}
        if self._size < self.capacity:
            order = torch.arange(self._size, device=self.device)
        else:
            order = (torch.arange(self.capacity, device=self.device) + self._ptr) % self.capacity
        return {k: v.index_select(0, order).cpu().numpy() for k, v in self._data.items()}

    def get_state(self) -> dict[str, Any]:
        """`FlatTransitionBuffer.get_state`'s format: filled rows in storage order (numpy), the write
        pointer and the counters."""
        filled = None
        if self._data is not None and self._size > 0:
            filled = {k: v[: self._size].cpu().numpy().copy() for k, v in self._data.items()}
        return {
            "capacity": self.capacity,
            "obs_dtype": np.dtype(np.float32).str,
            "obs_dim": self._obs_dim,
            "action_dim": self._action_dim,
            "num_added": self._num_added,
            "ptr": self._ptr,
            "size": self._size,
            "data": filled,
            "sampler": self.sampler.get_state(),
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores a `get_state` snapshot of either buffer (capacity, dims, rows, write pointer, and
        the sampler's counter where the snapshot has one: a numpy buffer's has none)."""
        super().set_state(state)
        self._size_t.fill_(self._size)
        if state.get("sampler") is not None:
            self.sampler.set_state(state["sampler"])
