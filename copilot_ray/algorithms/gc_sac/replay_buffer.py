"""The flat replay buffer of (goal-conditioned) SAC: N seeds' FIFO rings of transitions in torch tensors
on one device (the learner's; a CPU by default), sampled there with no host synchronisation.

Each row is one transition (obs, new_obs, actions, rewards, terminateds, truncateds). Observations
already contain the goal the agent was pursuing (the CO-PILOT env wrapper concatenates observation and
current sub-goal into one flat Box), so a transition of a sub-task is stored with that sub-task's goal.
Column names are RLlib's (`Columns.OBS == "obs"`, ...), so a sample can go straight into a `SampleBatch`.

Each column is one [N, capacity, ...] tensor (N = 1 for a one-seed run, N seeds for a stack), allocated
once at full capacity on the first `add`, so its address never moves while a captured CUDA graph reads
it (`storage_version` counts allocations; a captured step is rebuilt when it changes). `sample(B)` draws
B rows of each seed's own as one [N, B, ...] batch, one gather per column: row indices are
`floor(u * size)` for uniforms `u` from the seed's Philox stream (`philox.PhiloxStreams`, purpose
`SAMPLE_STREAM`: the same rows on every device, and for a seed whether its ring is alone or a row of a
stack), where `size` is a device tensor updated in place when rows are added. Adding is one
host-to-device copy per column to one seed's ring (`seed=i`); `get_state(seed=i)` is that ring as
numpy arrays and its sampler's counter.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import torch
from ray.rllib.core.columns import Columns

from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams

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


# The purpose word of the replay's row-sampling streams (a seed's noise streams have another).
SAMPLE_STREAM = 2


def uniform_rows(
    size: torch.Tensor, sampler: PhiloxStreams, batch_size: int, active: torch.Tensor | None = None
) -> torch.Tensor:
    """[N, batch_size] uniform row indices, row i in [0, size_i) from stream i of `sampler`, for an int64
    device tensor `size` ([N, 1]), without reading `size` on the host (float64 uniforms keep the rounding
    below one row). An empty ring's rows are 0 (its batch is not trained on); `active` ([N] bool): the
    streams that move (the others' rows are drawn but not consumed)."""
    u = sampler.uniform(int(batch_size), active, dtype=torch.float64)
    return torch.minimum((u * size).long(), (size - 1).clamp(min=0))


def gather_rows(column: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
    """column [N, capacity, ...] at rows [N, B] (each seed its own rows): [N, B, ...]."""
    n, b = rows.shape
    index = rows.view(n, b, *([1] * (column.dim() - 2))).expand(n, b, *column.shape[2:])
    return torch.gather(column, 1, index)


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
                "a FlatTransitionBuffer needs flat Box observations; got a Dict observation "
                "(flatten observation + goal in the env wrapper)"
            )
        obs = np.asarray(obs)
        if obs.shape[0] != t + 1:
            raise ValueError(f"episode {getattr(ep, 'id_', '?')}: {obs.shape[0]} observations for {t} steps")
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


class FlatTransitionBuffer:
    """N seeds' FIFO rings of flat transitions whose rows are torch tensors on `device` (module docstring).

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
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        self.capacity = int(capacity)
        self.device = torch.device(device)
        self.seeds = [int(seed)] if seeds is None else [int(s) for s in seeds]
        if not self.seeds:
            raise ValueError("a FlatTransitionBuffer needs at least one seed")
        self.num_seeds = n = len(self.seeds)
        self.sampler = PhiloxStreams(self.seeds, SAMPLE_STREAM, self.device)
        self.sizes = torch.zeros(n, dtype=torch.int64, device=self.device)  # what sampling reads
        self.storage_version = 0
        self._ptr, self._size, self._num_added = [0] * n, [0] * n, [0] * n  # each ring's host counters
        self._data: dict[str, torch.Tensor] | None = None
        self._obs_dim, self._action_dim = obs_dim, action_dim
        if obs_dim is not None and action_dim is not None:
            self._allocate(int(obs_dim), int(action_dim))

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

    def __len__(self) -> int:
        """The smallest seed's fill (a sample needs every seed it trains non-empty)."""
        return min(self._size)

    def size_of(self, seed: int) -> int:
        """Seed `seed`'s fill."""
        return self._size[seed]

    @property
    def num_added(self) -> int:
        """Transitions added over the buffer's lifetime (overwritten ones included), all seeds together."""
        return sum(self._num_added)

    @property
    def obs_dim(self) -> int | None:
        """Flat observation size (None until known)."""
        return self._obs_dim

    @property
    def action_dim(self) -> int | None:
        """Flat action size (None until known)."""
        return self._action_dim

    # ---------------------------------------------------------------- adding
    def add(self, transitions: Mapping[str, Any], seed: int = 0) -> int:
        """Adds a batch of transitions, a dict of equally long arrays, to seed `seed`'s ring (its index in
        `seeds`), then the device's copy of its size. Required keys: obs, new_obs, actions, rewards;
        optional: terminateds, truncateds (False when absent). Returns the number of rows added."""
        cols = self._checked_columns(transitions)
        if cols is None:
            return 0
        n = len(cols[OBS])
        for start, rows in ring_segments(self._ptr[seed], n, self.capacity):
            for key, values in cols.items():
                target = self._data[key][seed, start : start + (rows.stop - rows.start)]
                target.copy_(torch.from_numpy(np.ascontiguousarray(values[rows])).to(target.dtype))
        self._ptr[seed], self._size[seed] = ring_advance(self._ptr[seed], self._size[seed], n, self.capacity)
        self._num_added[seed] += n
        self.sizes[seed].fill_(self._size[seed])
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
        term, trunc = (transitions.get(k) for k in (TERMINATEDS, TRUNCATEDS))
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

    def add_episodes(self, episodes: Iterable[Any], seed: int = 0) -> int:
        """Adds RLlib `SingleAgentEpisode`s (e.g. from `EnvRunner.sample()`) to seed `seed`'s ring;
        returns rows added."""
        transitions = episodes_to_transitions(episodes)
        return self.add(transitions, seed) if transitions else 0

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
        order = torch.arange(size, device=self.device)
        if size == self.capacity:
            order = (order + ptr) % self.capacity
        return {k: v[seed].index_select(0, order).cpu().numpy() for k, v in self._data.items()}

    def get_state(self, seed: int = 0) -> dict[str, Any]:
        """A picklable snapshot of seed `seed`'s ring: its filled rows in storage order as numpy, the
        write pointer, the counters and its sampler's counter, so a restored ring samples exactly the
        same rows."""
        filled = None
        if self._data is not None and self._size[seed] > 0:
            filled = {k: v[seed, : self._size[seed]].cpu().numpy().copy() for k, v in self._data.items()}
        return {
            "capacity": self.capacity,
            "obs_dim": self._obs_dim,
            "action_dim": self._action_dim,
            "num_added": self._num_added[seed],
            "ptr": self._ptr[seed],
            "size": self._size[seed],
            "data": filled,
            "sampler": self.sampler.stream(seed).get_state(),
        }

    def set_state(self, state: Mapping[str, Any], seed: int = 0) -> None:
        """Restores a one-seed snapshot into seed `seed`'s ring (its rows, write pointer, counters and
        sampler's counter). A one-seed buffer takes another capacity (its storage is reallocated); a
        stack refuses it, and other sizes, before changing anything."""
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
