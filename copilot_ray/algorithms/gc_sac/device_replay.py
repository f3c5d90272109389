"""`FlatTransitionBuffer`'s twin whose rows live in torch tensors on the learner's device.

Sampling happens on that device with no host synchronisation, so it can sit inside the fused SAC step
and its CUDA graph: row indices are `floor(u * size)` for uniform `u` from torch's generator of the
device, where `size` is a 0-d device tensor updated in place when rows are added. The storage is
allocated once at full capacity (on the first `add`), so its address never moves while a graph reads
it; `storage_version` counts (re)allocations, and a captured step is rebuilt when it changes.

Adding is one host-to-device copy per column per call. The state (`get_state`) has
`FlatTransitionBuffer`'s format, numpy arrays included, so either buffer restores the other's
checkpoint.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import torch

from copilot_ray.algorithms.gc_sac.replay_buffer import (
    ACTIONS,
    COLUMNS,
    NEXT_OBS,
    OBS,
    REWARDS,
    TERMINATEDS,
    TRAIN_COLUMNS,
    TRUNCATEDS,
    FlatTransitionBuffer,
)


def uniform_rows(size: torch.Tensor, batch_size: int | tuple[int, ...], device: torch.device) -> torch.Tensor:
    """`batch_size` uniform row indices in [0, size) for an int64 device tensor `size` >= 1 (0-d, or
    [N, 1] with batch_size (N, B): each row of indices under its own size), without reading `size` on
    the host (float64 uniforms keep the rounding below one row)."""
    u = torch.rand(batch_size, device=device, dtype=torch.float64)
    return torch.minimum((u * size).long(), size - 1)


class DeviceTransitionBuffer:
    """A fixed-capacity FIFO ring of flat transitions in torch tensors on `device` (module docstring).

    Args:
        capacity: transitions kept; the oldest are overwritten first.
        device: where the rows live and are sampled (the learner's device).
        obs_dim, action_dim: flat sizes; inferred from the first `add` when None.
    """

    def __init__(
        self,
        capacity: int,
        device: torch.device | str = "cpu",
        obs_dim: int | None = None,
        action_dim: int | None = None,
    ):
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self.capacity = int(capacity)
        self.device = torch.device(device)
        self._obs_dim, self._action_dim = obs_dim, action_dim
        self._data: dict[str, torch.Tensor] | None = None
        self._ptr = 0
        self._size = 0
        self._num_added = 0
        self._size_t = torch.zeros((), dtype=torch.int64, device=self.device)
        self.storage_version = 0
        if obs_dim is not None and action_dim is not None:
            self._allocate(int(obs_dim), int(action_dim))

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

    def __len__(self) -> int:
        return self._size

    @property
    def num_added(self) -> int:
        """Transitions added over the buffer's lifetime (including overwritten ones)."""
        return self._num_added

    @property
    def obs_dim(self) -> int | None:
        return self._obs_dim

    @property
    def action_dim(self) -> int | None:
        return self._action_dim

    # ---------------------------------------------------------------- adding
    def add(self, transitions: Mapping[str, Any]) -> int:
        """Adds a batch of transitions (a dict of equally long arrays; `FlatTransitionBuffer.add`'s
        keys and rules). Returns the number of rows added."""
        obs = np.asarray(transitions[OBS])
        n = int(obs.shape[0])
        if n == 0:
            return 0
        obs = obs.reshape(n, -1)
        actions = np.asarray(transitions[ACTIONS]).reshape(n, -1)
        if self._data is None:
            self._allocate(obs.shape[1], actions.shape[1])
        cols = {
            OBS: obs,
            NEXT_OBS: np.asarray(transitions[NEXT_OBS]).reshape(n, -1),
            ACTIONS: actions,
            REWARDS: np.asarray(transitions[REWARDS], dtype=np.float32).reshape(n),
        }
        for key in (TERMINATEDS, TRUNCATEDS):
            flags = transitions.get(key)
            cols[key] = np.zeros(n, bool) if flags is None else np.asarray(flags, dtype=bool).reshape(n)
        for key in (OBS, NEXT_OBS):
            if cols[key].shape[1] != self._obs_dim:
                raise ValueError(f"observation size {cols[key].shape[1]} != buffer obs_dim {self._obs_dim}")
        if actions.shape[1] != self._action_dim:
            raise ValueError(f"action size {actions.shape[1]} != buffer action_dim {self._action_dim}")
        if n >= self.capacity:  # only the newest `capacity` rows survive
            cols = {k: v[n - self.capacity :] for k, v in cols.items()}
            self._write(0, cols)
            self._ptr, self._size = 0, self.capacity
        else:
            first = min(n, self.capacity - self._ptr)
            self._write(self._ptr, {k: v[:first] for k, v in cols.items()})
            if first < n:
                self._write(0, {k: v[first:] for k, v in cols.items()})
            self._ptr = (self._ptr + n) % self.capacity
            self._size = min(self._size + n, self.capacity)
        self._num_added += n
        self._size_t.fill_(self._size)
        return n

    def _write(self, start: int, cols: Mapping[str, np.ndarray]) -> None:
        for key, values in cols.items():
            target = self._data[key][start : start + len(values)]
            target.copy_(torch.from_numpy(np.ascontiguousarray(values)).to(target.dtype), non_blocking=False)

    def add_episodes(self, episodes: Iterable[Any]) -> int:
        """Adds RLlib `SingleAgentEpisode`s (as `FlatTransitionBuffer.add_episodes`); returns rows added."""
        transitions = FlatTransitionBuffer.episodes_to_transitions(episodes)
        return self.add(transitions) if transitions else 0

    # ---------------------------------------------------------------- sampling
    def sample(self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions (with replacement) as device tensors, no host sync. The
        caller makes sure the buffer is not empty (`len(buffer) > 0`, a host-side count)."""
        rows = uniform_rows(self._size_t, int(batch_size), self.device)
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
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores a `get_state` snapshot of either buffer (capacity, dims, rows, write pointer)."""
        self.capacity = int(state["capacity"])
        self._data, self._ptr, self._size = None, 0, 0
        self._obs_dim, self._action_dim = state["obs_dim"], state["action_dim"]
        self._num_added = int(state["num_added"])
        if self._obs_dim is not None and self._action_dim is not None:
            self._allocate(int(self._obs_dim), int(self._action_dim))
        if state.get("data"):
            size = int(state["size"])
            self._write(0, {k: np.asarray(v)[:size] for k, v in state["data"].items() if k in COLUMNS})
            self._size, self._ptr = size, int(state["ptr"])
        self._size_t.fill_(self._size)
