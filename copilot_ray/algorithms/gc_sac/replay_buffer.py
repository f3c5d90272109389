"""A flat numpy ring buffer of transitions for (goal-conditioned) SAC.

Each row is one transition (obs, new_obs, actions, rewards, terminateds, truncateds). Observations
already contain the goal the agent was pursuing (the CO-PILOT env wrapper concatenates observation and
current sub-goal into one flat Box), so a transition of a sub-task is stored with that sub-task's goal.

Sampling `n` transitions is one fancy-indexing call per column (tens of microseconds for 256 rows out
of 1 M), against tens of milliseconds for RLlib's episode replay buffer plus its learner connector.
Column names are RLlib's (`Columns.OBS == "obs"`, `Columns.NEXT_OBS == "new_obs"`, ...), so a sample
can go straight into a `SampleBatch`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from ray.rllib.core.columns import Columns

OBS = Columns.OBS  # "obs"
NEXT_OBS = Columns.NEXT_OBS  # "new_obs"
ACTIONS = Columns.ACTIONS  # "actions"
REWARDS = Columns.REWARDS  # "rewards"
TERMINATEDS = Columns.TERMINATEDS  # "terminateds"
TRUNCATEDS = Columns.TRUNCATEDS  # "truncateds"

COLUMNS = (OBS, NEXT_OBS, ACTIONS, REWARDS, TERMINATEDS, TRUNCATEDS)
# The columns a SAC learner needs (truncation does not enter the loss: a truncated transition
# bootstraps from its next observation like any non-terminal one).
TRAIN_COLUMNS = (OBS, NEXT_OBS, ACTIONS, REWARDS, TERMINATEDS)


def ring_segments(ptr: int, n: int, capacity: int) -> list[tuple[int, slice]]:
    """Where n new rows go in a ring of `capacity` whose next row is `ptr`: [(storage start, slice of
    the new rows)], at most two; of more than `capacity` rows only the newest survive, from row 0."""
    if n >= capacity:
        return [(0, slice(n - capacity, n))]
    first = min(n, capacity - ptr)
    return [(ptr, slice(0, first))] + ([(0, slice(first, n))] if first < n else [])


def ring_advance(ptr: int, size: int, n: int, capacity: int) -> tuple[int, int]:
    """The ring's (next row, fill) after n more rows."""
    if n >= capacity:
        return 0, capacity
    return (ptr + n) % capacity, min(size + n, capacity)


class FlatTransitionBuffer:
    """Fixed-capacity FIFO ring buffer of flat transitions, stored column-wise in numpy arrays.

    Args:
        capacity: Maximum number of transitions; the oldest are overwritten first.
        obs_dim: Observation size (flat). Inferred from the first `add` when None.
        action_dim: Action size (flat). Inferred from the first `add` when None.
        obs_dtype: dtype of stored observations (float32 by default).
    """

    def __init__(
        self,
        capacity: int,
        obs_dim: int | None = None,
        action_dim: int | None = None,
        obs_dtype: Any = np.float32,
    ):
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self.capacity = int(capacity)
        self.obs_dtype = np.dtype(obs_dtype)
        self._obs_dim = obs_dim
        self._action_dim = action_dim
        self._data: dict[str, np.ndarray] | None = None
        self._ptr = 0  # next row to write
        self._size = 0
        self._num_added = 0  # lifetime transitions added
        if obs_dim is not None and action_dim is not None:
            self._allocate(int(obs_dim), int(action_dim))

    # ---------------------------------------------------------------- storage
    def _allocate(self, obs_dim: int, action_dim: int) -> None:
        c = self.capacity
        self._obs_dim, self._action_dim = obs_dim, action_dim
        self._data = {
            OBS: np.zeros((c, obs_dim), dtype=self.obs_dtype),
            NEXT_OBS: np.zeros((c, obs_dim), dtype=self.obs_dtype),
            ACTIONS: np.zeros((c, action_dim), dtype=np.float32),
            REWARDS: np.zeros((c,), dtype=np.float32),
            TERMINATEDS: np.zeros((c,), dtype=bool),
            TRUNCATEDS: np.zeros((c,), dtype=bool),
        }

    def __len__(self) -> int:
        return self._size

    @property
    def num_added(self) -> int:
        """Transitions added over the buffer's lifetime (including overwritten ones)."""
        return self._num_added

    @property
    def obs_dim(self) -> int | None:
        """Flat observation size (None until known)."""
        return self._obs_dim

    @property
    def action_dim(self) -> int | None:
        """Flat action size (None until known)."""
        return self._action_dim

    # ---------------------------------------------------------------- adding
    def add(self, transitions: Mapping[str, Any]) -> int:
        """Adds a batch of transitions given as a dict of equally long arrays.

        Required keys: obs, new_obs, actions, rewards; optional: terminateds, truncateds (False when
        absent). Observations/actions are reshaped to (n, -1). Returns the number of rows added.
        """
        cols = self._checked_columns(transitions)
        if cols is None:
            return 0
        n = len(cols[OBS])
        for start, rows in ring_segments(self._ptr, n, self.capacity):
            self._write(start, {k: v[rows] for k, v in cols.items()})
        self._ptr, self._size = ring_advance(self._ptr, self._size, n, self.capacity)
        self._num_added += n
        return n

    def _checked_columns(self, transitions: Mapping[str, Any]) -> dict[str, np.ndarray] | None:
        """`transitions` as the six stored columns, shapes checked against the buffer's (allocated on
        the first add); None for an empty batch."""
        obs = np.asarray(transitions[OBS])
        n = int(obs.shape[0])
        if n == 0:
            return None
        obs = obs.reshape(n, -1)
        next_obs = np.asarray(transitions[NEXT_OBS]).reshape(n, -1)
        actions = np.asarray(transitions[ACTIONS]).reshape(n, -1)
        rewards = np.asarray(transitions[REWARDS], dtype=np.float32).reshape(n)
        term = transitions.get(TERMINATEDS)
        trunc = transitions.get(TRUNCATEDS)
        term = np.zeros(n, bool) if term is None else np.asarray(term, dtype=bool).reshape(n)
        trunc = np.zeros(n, bool) if trunc is None else np.asarray(trunc, dtype=bool).reshape(n)
        if self._data is None:
            self._allocate(obs.shape[1], actions.shape[1])
        if obs.shape[1] != self._obs_dim or next_obs.shape[1] != self._obs_dim:
            raise ValueError(f"observation size {obs.shape[1]} != buffer obs_dim {self._obs_dim}")
        if actions.shape[1] != self._action_dim:
            raise ValueError(f"action size {actions.shape[1]} != buffer action_dim {self._action_dim}")
        return {
            OBS: obs,
            NEXT_OBS: next_obs,
            ACTIONS: actions,
            REWARDS: rewards,
            TERMINATEDS: term,
            TRUNCATEDS: trunc,
        }

    def _write(self, start: int, cols: Mapping[str, np.ndarray]) -> None:
        """Stores equally long `cols` at storage rows start, start + 1, ... (the storage's only writer)."""
        for key, values in cols.items():
            self._data[key][start : start + len(values)] = values

    @staticmethod
    def episodes_to_transitions(episodes: Iterable[Any]) -> dict[str, np.ndarray]:
        """Converts RLlib `SingleAgentEpisode`s (or chunks of ongoing ones) to flat transition arrays.

        A chunk with T steps has T actions/rewards and T + 1 observations (its lookback buffer is
        excluded; RLlib's `get_observations()` already returns the final next-obs, also for truncated
        episodes). Only the chunk's last transition can be terminated/truncated, per
        `episode.is_terminated` / `episode.is_truncated`. Per-episode work is a few array slices; there
        is no per-transition Python loop.
        """
        obs_l, nobs_l, act_l, rew_l, term_l, trunc_l = [], [], [], [], [], []
        for ep in episodes:
            t = len(ep)
            if t == 0:
                continue
            obs = ep.get_observations()
            if isinstance(obs, Mapping):
                raise TypeError(
                    "FlatTransitionBuffer needs flat Box observations; got a Dict observation "
                    "(flatten observation + goal in the env wrapper)"
                )
            obs = np.asarray(obs)
            if obs.shape[0] != t + 1:
                raise ValueError(
                    f"episode {getattr(ep, 'id_', '?')}: {obs.shape[0]} observations for {t} steps"
                )
            obs = obs.reshape(t + 1, -1)
            obs_l.append(obs[:-1])
            nobs_l.append(obs[1:])
            act_l.append(np.asarray(ep.get_actions()).reshape(t, -1))
            rew_l.append(np.asarray(ep.get_rewards(), dtype=np.float32).reshape(t))
            term = np.zeros(t, dtype=bool)
            trunc = np.zeros(t, dtype=bool)
            term[-1] = bool(ep.is_terminated)
            trunc[-1] = bool(ep.is_truncated) and not term[-1]
            term_l.append(term)
            trunc_l.append(trunc)
        if not obs_l:
            return {}
        return {
            OBS: np.concatenate(obs_l),
            NEXT_OBS: np.concatenate(nobs_l),
            ACTIONS: np.concatenate(act_l).astype(np.float32, copy=False),
            REWARDS: np.concatenate(rew_l),
            TERMINATEDS: np.concatenate(term_l),
            TRUNCATEDS: np.concatenate(trunc_l),
        }

    def add_episodes(self, episodes: Iterable[Any]) -> int:
        """Adds RLlib `SingleAgentEpisode`s (e.g. from `EnvRunner.sample()`); returns rows added."""
        transitions = self.episodes_to_transitions(episodes)
        return self.add(transitions) if transitions else 0

    # ---------------------------------------------------------------- sampling
    def sample_indices(self, batch_size: int, rng: np.random.Generator) -> np.ndarray:
        """`batch_size` uniform row indices (with replacement) into the filled part of the buffer."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty FlatTransitionBuffer")
        return rng.integers(0, self._size, size=int(batch_size))

    def sample(
        self,
        batch_size: int,
        rng: np.random.Generator,
        columns: Iterable[str] = COLUMNS,
    ) -> dict[str, np.ndarray]:
        """Uniformly samples `batch_size` transitions (with replacement) -> dict of column arrays."""
        idx = self.sample_indices(batch_size, rng)
        return {k: self._data[k][idx] for k in columns}

    # ---------------------------------------------------------------- state
    def transitions(self) -> dict[str, np.ndarray]:
        """All stored transitions, oldest first (copies)."""
        if self._data is None or self._size == 0:
            return {}
        if self._size < self.capacity:
            order = np.arange(self._size)
        else:
            order = (np.arange(self.capacity) + self._ptr) % self.capacity
        return {k: v[order] for k, v in self._data.items()}

    def get_state(self) -> dict[str, Any]:
        """A picklable snapshot: the filled rows in storage order plus the write pointer, so a
        restored buffer samples exactly the same rows for the same rng."""
        filled = None
        if self._data is not None and self._size > 0:
            filled = {k: v[: self._size].copy() for k, v in self._data.items()}
        return {
            "capacity": self.capacity,
            "obs_dtype": self.obs_dtype.str,
            "obs_dim": self._obs_dim,
            "action_dim": self._action_dim,
            "num_added": self._num_added,
            "ptr": self._ptr,
            "size": self._size,
            "data": filled,
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restores a `get_state` snapshot (capacity, dims, rows, write pointer)."""
        self.capacity = int(state["capacity"])
        self.obs_dtype = np.dtype(state["obs_dtype"])
        self._data, self._ptr, self._size = None, 0, 0
        self._obs_dim, self._action_dim = state["obs_dim"], state["action_dim"]
        self._num_added = int(state["num_added"])
        if self._obs_dim is not None and self._action_dim is not None:
            self._allocate(int(self._obs_dim), int(self._action_dim))
        if state.get("data"):
            size = int(state["size"])
            self._write(0, {k: np.asarray(v)[:size] for k, v in state["data"].items() if k in COLUMNS})
            self._size, self._ptr = size, int(state["ptr"])

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> FlatTransitionBuffer:
        """A new buffer restored from a `get_state` snapshot."""
        buf = cls(capacity=int(state["capacity"]))
        buf.set_state(state)
        return buf

    def __getstate__(self) -> dict[str, Any]:
        return self.get_state()

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.set_state(state)
