"""The high level's replay: transitions (s_t, g, offset, sum of rewards, s_{t+c}) that keep the low-level
segment behind them, so that a sampled offset can be relabelled by HIRO's off-policy correction.

A sample has the flat replay's columns (obs, new_obs, actions, rewards, terminateds), so
`gc_sac.update_from_buffer` drives the high level's learner from it unchanged; the correction runs when
a batch is sampled (with the current low level), as in HIRO.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np

from copilot_ray.algorithms.gc_sac.replay_buffer import ACTIONS, TRAIN_COLUMNS, TRUNCATEDS

# The columns `add` takes: the SAC transition, and the segment (start/end achieved goal, the low level's
# raw observations, achieved goals and actions at each of its c steps, and which steps happened).
SEGMENT_COLUMNS = ("start", "end", "seg_obs", "seg_achieved", "seg_actions", "seg_mask")
# (sampled rows' columns, rng) -> (relabelled actions [n, g], whether each kept its stored action [n])
Corrector = Callable[[Mapping[str, np.ndarray], np.random.Generator], tuple[np.ndarray, np.ndarray]]


class SegmentReplayBuffer:
    """A FIFO ring buffer of high-level transitions with their segments; `corrector` (settable later,
    None: no correction) relabels the actions of every sampled batch."""

    def __init__(self, capacity: int, corrector: Corrector | None = None):
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self.capacity = int(capacity)
        self.corrector = corrector
        self._data: dict[str, np.ndarray] | None = None
        self._ptr = 0
        self._size = 0
        self._num_added = 0
        self.num_corrected = 0  # sampled transitions that went through the correction
        self.num_kept = 0  # ... and kept their stored offset

    def __len__(self) -> int:
        return self._size

    @property
    def num_added(self) -> int:
        return self._num_added

    def add(self, columns: Mapping[str, np.ndarray]) -> int:
        """A batch of transitions: TRAIN_COLUMNS plus SEGMENT_COLUMNS, equally long. Returns rows added."""
        missing = sorted(set(TRAIN_COLUMNS + SEGMENT_COLUMNS) - set(columns))
        if missing:
            raise ValueError(f"SegmentReplayBuffer.add: missing columns {missing}")
        cols = {k: np.asarray(columns[k]) for k in TRAIN_COLUMNS + SEGMENT_COLUMNS}
        n = len(cols[ACTIONS])
        if n == 0:
            return 0
        if n > self.capacity:
            cols = {k: v[n - self.capacity :] for k, v in cols.items()}
            n = self.capacity
        if self._data is None:
            self._data = {k: np.zeros((self.capacity, *v.shape[1:]), v.dtype) for k, v in cols.items()}
        rows = (self._ptr + np.arange(n)) % self.capacity
        for k, v in cols.items():
            self._data[k][rows] = v
        self._ptr = (self._ptr + n) % self.capacity
        self._size = min(self._size + n, self.capacity)
        self._num_added += n
        return n

    def sample(
        self, batch_size: int, rng: np.random.Generator, columns: Iterable[str] = TRAIN_COLUMNS
    ) -> dict[str, np.ndarray]:
        """`batch_size` uniform transitions (with replacement), actions relabelled by the corrector."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty SegmentReplayBuffer")
        rows = rng.integers(0, self._size, size=int(batch_size))
        out = {k: v[rows] for k, v in self._data.items()}
        if self.corrector is not None:
            out[ACTIONS], kept = self.corrector(out, rng)
            self.num_corrected += len(rows)
            self.num_kept += int(np.count_nonzero(kept))
        out[TRUNCATEDS] = np.zeros(len(rows), bool)
        return {k: out[k] for k in columns}

    def get_state(self) -> dict[str, Any]:
        filled = None if self._data is None else {k: v[: self._size].copy() for k, v in self._data.items()}
        return {
            "capacity": self.capacity,
            "ptr": self._ptr,
            "size": self._size,
            "num_added": self._num_added,
            "num_corrected": self.num_corrected,
            "num_kept": self.num_kept,
            "data": filled,
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores a `get_state` snapshot (the corrector stays: it is the algorithm's, not data)."""
        if int(state["capacity"]) != self.capacity:
            raise ValueError(f"a checkpoint of capacity {state['capacity']} into a buffer of {self.capacity}")
        self._data = None
        if state["data"] is not None:
            self._data = {
                k: np.zeros((self.capacity, *v.shape[1:]), v.dtype) for k, v in state["data"].items()
            }
            for k, v in state["data"].items():
                self._data[k][: len(v)] = v
        self._ptr, self._size, self._num_added = (
            int(state["ptr"]),
            int(state["size"]),
            int(state["num_added"]),
        )
        self.num_corrected, self.num_kept = int(state["num_corrected"]), int(state["num_kept"])
