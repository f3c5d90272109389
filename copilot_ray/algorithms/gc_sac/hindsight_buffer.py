"""Hindsight experience replay (HER) as a replay buffer, as Stable-Baselines3 does it: the algorithm
stays SAC, only the transitions it learns from change.

Transitions are stored whole episodes at a time with their raw parts (observation, achieved goal,
desired goal, collision flag) and the position of each step in its episode, in torch tensors on one
device (the learner's; a CPU by default), a ring per seed: every stored column is one [N, capacity, ...]
tensor (N = 1 for one seed). `sample(B)` draws B uniform rows of each seed's own (the flat buffer's
`uniform_rows`); a share `n_sampled_goal / (n_sampled_goal + 1)` of them (SB3's `her_ratio`) gets a new
goal achieved later in the same episode (`future`), at its end (`final`) or anywhere in it (`episode`),
and their reward and termination are recomputed in one batch by a torch `reward_fn` (the goal env's
reward under the traversal rules), the dense reward added back. The agent's flat input is put together
at sampling time, so the relabelled goal also enters the goal - achieved part of
`agent_input="state_goal_delta"`. All of it runs on the device without a host synchronisation, so it can
sit inside the fused SAC step and its CUDA graph; rows and goals come from the seed's Philox stream
(`replay_buffer.SAMPLE_STREAM`), in that order each call.

A sample has the flat buffer's columns (obs, new_obs, actions, rewards, terminateds), so either buffer
drives the learner.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from copilot_ray.algorithms.gc_sac.philox import PhiloxStreams
from copilot_ray.algorithms.gc_sac.replay_buffer import (
    ACTIONS,
    NEXT_OBS,
    OBS,
    REWARDS,
    SAMPLE_STREAM,
    TERMINATEDS,
    TRAIN_COLUMNS,
    TRUNCATEDS,
    gather_rows,
    uniform_rows,
)
from copilot_ray.envs.goal_observation import flat_observation

GOAL_SELECTIONS = ("future", "final", "episode")
# (next achieved goals [n, g], goals [n, g], collisions bool [n]) -> (rewards [n], terminateds bool [n]),
# torch tensors on the buffer's device, no host synchronisation.
TorchRewardFn = Callable[[torch.Tensor, torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]]


@dataclass(frozen=True)
class GoalLayout:
    """Where the observation and the goal sit in the agent's flat input (concat(observation, goal[,
    goal - achieved]), see `copilot_ray.envs.goal_observation`)."""

    obs_dim: int
    goal_dim: int
    with_delta: bool = False

    @property
    def flat_dim(self) -> int:
        return self.obs_dim + self.goal_dim * (2 if self.with_delta else 1)

    def split(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(observation, goal) of flat inputs [n, flat_dim]."""
        if flat.shape[-1] != self.flat_dim:
            raise ValueError(f"flat observation of size {flat.shape[-1]}, expected {self.flat_dim} ({self})")
        return flat[..., : self.obs_dim], flat[..., self.obs_dim : self.obs_dim + self.goal_dim]

    def compose(self, observation: np.ndarray, goal: np.ndarray, achieved: np.ndarray) -> np.ndarray:
        return flat_observation(observation, goal, achieved if self.with_delta else None)


STORED_COLUMNS = {  # column -> (width: "obs" | "goal" | "action" | None for scalars, dtype)
    "observation": ("obs", np.float32),
    "next_observation": ("obs", np.float32),
    "achieved": ("goal", np.float32),
    "next_achieved": ("goal", np.float32),
    "goal": ("goal", np.float32),
    ACTIONS: ("action", np.float32),
    REWARDS: (None, np.float32),
    TERMINATEDS: (None, bool),
    "collision": (None, bool),
    # The goal env's goal-independent per-step reward (info["dense_reward"], e.g. the walker's own),
    # part of the stored reward and added back to a relabelled one.
    "dense": (None, np.float32),
    "episode_start": (None, np.int64),  # lifetime index of the episode's first transition
    "episode_length": (None, np.int64),
    "step": (None, np.int64),  # position in the episode, 0-based
}


STORED_COLUMNS = {  # column -> (width: "obs" | "goal" | "action" | None for scalars, dtype)
    "observation": ("obs", torch.float32),
    "next_observation": ("obs", torch.float32),
    "achieved": ("goal", torch.float32),
    "next_achieved": ("goal", torch.float32),
    "goal": ("goal", torch.float32),
    ACTIONS: ("action", torch.float32),
    REWARDS: (None, torch.float32),
    TERMINATEDS: (None, torch.bool),
    "collision": (None, torch.bool),
    # The goal env's goal-independent per-step reward (info["dense_reward"], e.g. the walker's own),
    # part of the stored reward and added back to a relabelled one.
    "dense": (None, torch.float32),
    "episode_start": (None, torch.int64),  # lifetime index of the episode's first transition
    "episode_length": (None, torch.int64),
    "step": (None, torch.int64),  # position in the episode, 0-based
}


class HindsightReplayBuffer:
    """N seeds' rings of whole episodes that relabel goals when sampled (module docstring).

    Args:
        capacity: transitions kept per seed; the oldest are overwritten first (an episode's later
            transitions are always newer, so a `future` goal never points at an overwritten row).
        layout: where observation and goal sit in the flat input.
        reward_fn: batched (rewards, terminateds) for relabelled goals, on the device.
        n_sampled_goal: relabelled goals per real one (SB3's default 4: 80 % of a batch relabelled);
            0 samples the stored transitions only.
        goal_selection: "future" (SB3's default), "final" or "episode".
        device: where the rows live and are sampled.
        seed: keys the sampler's stream of a one-seed buffer; seeds: one per ring, for N seeds.
    """

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
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        if int(n_sampled_goal) < 0:
            raise ValueError(f"n_sampled_goal must be >= 0, got {n_sampled_goal}")
        if goal_selection not in GOAL_SELECTIONS:
            raise ValueError(
                f"goal_selection={goal_selection!r} is invalid: use one of {list(GOAL_SELECTIONS)}"
            )
        self.seeds = [int(seed)] if seeds is None else [int(s) for s in seeds]
        if not self.seeds:
            raise ValueError("a HindsightReplayBuffer needs at least one seed")
        self.capacity = int(capacity)
        self.layout = layout
        self.reward_fn = reward_fn
        self.n_sampled_goal = int(n_sampled_goal)
        self.her_ratio = 1.0 - 1.0 / (self.n_sampled_goal + 1)
        self.goal_selection = goal_selection
        self.device = torch.device(device)
        self.num_seeds = n = len(self.seeds)
        self.sampler = PhiloxStreams(self.seeds, SAMPLE_STREAM, self.device)
        self.sizes = torch.zeros(n, dtype=torch.int64, device=self.device)  # what sampling reads
        self.pointers = torch.zeros(n, dtype=torch.int64, device=self.device)  # for "episode"
        self.storage_version = 0
        self._ptr, self._size, self._num_added = [0] * n, [0] * n, [0] * n  # each ring's host counters
        self._storage: dict[str, torch.Tensor] | None = None
        self._action_dim: int | None = None

    def _allocate(self, action_dim: int, seed: int) -> None:
        """The storage of every ring, at the first episode or restore (a one-seed buffer reallocates
        for another action size; a stack refuses it)."""
        if self._storage is not None and int(action_dim) == self._action_dim:
            return
        if self._storage is not None and self.num_seeds > 1:
            raise ValueError(
                f"seed {self.seeds[seed]}: action size {action_dim} does not fit the stack's "
                f"{self._action_dim}"
            )
        self._action_dim = int(action_dim)
        widths = {"obs": self.layout.obs_dim, "goal": self.layout.goal_dim, "action": self._action_dim}
        rows = (self.num_seeds, self.capacity)
        self._storage = {
            name: torch.zeros(rows if w is None else (*rows, widths[w]), dtype=dtype, device=self.device)
            for name, (w, dtype) in STORED_COLUMNS.items()
        }
        self.storage_version += 1

    def _write_rows(self, seed: int, rows: np.ndarray, cols: Mapping[str, np.ndarray]) -> None:
        """Stores `cols` (column -> values, one per row) at ring `seed`'s rows `rows`."""
        index = torch.as_tensor(np.asarray(rows, np.int64), device=self.device)
        for name, values in cols.items():
            column = self._storage[name][seed]
            column.index_copy_(
                0, index, torch.as_tensor(np.ascontiguousarray(values)).to(self.device, column.dtype)
            )

    def _moved(self, seed: int) -> None:
        """The device's copies of ring `seed`'s fill and write pointer (what sampling reads)."""
        self.sizes[seed].fill_(self._size[seed])
        self.pointers[seed].fill_(self._ptr[seed])

    def __len__(self) -> int:
        """The smallest ring's fill (a sample needs every seed it trains non-empty)."""
        return min(self._size)

    def size_of(self, seed: int) -> int:
        """Ring `seed`'s fill."""
        return self._size[seed]

    @property
    def num_added(self) -> int:
        """Transitions added over the buffer's lifetime, all rings together."""
        return sum(self._num_added)

    # ------------------------------------------------------------------------------------ adding
    def add_episode(
        self,
        observations: np.ndarray,
        achieved: np.ndarray,
        goal: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        terminated: bool,
        collisions: np.ndarray,
        dense: np.ndarray | None = None,
        seed: int = 0,
    ) -> int:
        """One episode (or its first T steps) into ring `seed`: T + 1 raw observations and achieved
        goals, its goal, T actions, rewards and collision flags (and goal-independent dense rewards,
        default 0); `terminated`: whether its last step ended it. Returns T."""
        if not 0 <= int(seed) < self.num_seeds:
            raise ValueError(f"seed index {seed} is not one of this buffer's {self.num_seeds} rings")
        t = len(actions)
        if t == 0:
            return 0
        if len(observations) != t + 1 or len(achieved) != t + 1:
            raise ValueError(f"an episode of {t} steps needs {t + 1} observations and achieved goals")
        actions = np.asarray(actions, np.float32).reshape(t, -1)
        if self._storage is None:
            self._allocate(actions.shape[1], seed)
        if actions.shape[1] != self._action_dim:
            raise ValueError(f"action size {actions.shape[1]} != buffer action size {self._action_dim}")
        if t > self.capacity:
            raise ValueError(f"an episode of {t} steps does not fit a buffer of {self.capacity}")
        term = np.zeros(t, bool)
        term[-1] = bool(terminated)
        cols = {
            "observation": observations[:-1],
            "next_observation": observations[1:],
            "achieved": achieved[:-1],
            "next_achieved": achieved[1:],
            "goal": np.broadcast_to(goal, (t, self.layout.goal_dim)),
            ACTIONS: actions,
            REWARDS: rewards,
            TERMINATEDS: term,
            "collision": collisions,
            "dense": np.zeros(t, np.float32) if dense is None else dense,
            "episode_start": np.full(t, self._num_added[seed], np.int64),
            "episode_length": np.full(t, t, np.int64),
            "step": np.arange(t),
        }
        ptr = self._ptr[seed]
        self._write_rows(seed, (ptr + np.arange(t)) % self.capacity, cols)
        self._ptr[seed] = (ptr + t) % self.capacity
        self._size[seed] = min(self._size[seed] + t, self.capacity)
        self._num_added[seed] += t
        self._moved(seed)
        return t

    def add_episodes(self, episodes: Iterable[Any], seed: int = 0) -> int:
        """RLlib `SingleAgentEpisode`s of the traversal env into ring `seed`; their infos carry
        `achieved_goal` (reset and every step) and `collision` (every step). Returns the transitions added."""
        added = 0
        for ep in episodes:
            t = len(ep)
            if t == 0:
                continue
            flat = np.asarray(ep.get_observations()).reshape(t + 1, -1)
            infos = ep.get_infos()
            if "achieved_goal" not in infos[0]:
                raise ValueError(
                    "HindsightReplayBuffer needs info['achieved_goal'] at reset and every step "
                    "(copilot_ray's TraversalEnv provides it)"
                )
            observations, goals = self.layout.split(flat)
            added += self.add_episode(
                observations,
                np.stack([info["achieved_goal"] for info in infos]),
                goals[0],
                np.asarray(ep.get_actions()),
                np.asarray(ep.get_rewards(), np.float32),
                bool(ep.is_terminated),
                np.array([bool(info.get("collision", False)) for info in infos[1:]]),
                np.array([float(info.get("dense_reward", 0.0)) for info in infos[1:]], np.float32),
                seed=seed,
            )
        return added

    # ------------------------------------------------------------------------------------ sampling
    def write_pointers(self) -> torch.Tensor:
        """Each ring's next row, [N, 1] on the device (against [N, B] sampled rows; a captured step
        reads it as the buffer fills)."""
        return self.pointers.unsqueeze(1)

    def sample(
        self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS, active: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions of each seed's own, the first her_ratio of them with
        hindsight goals, as the agent's flat columns: [N, batch_size, ...] device tensors, no host sync.
        Rows, then goals, from each seed's stream; only the `active` seeds' ([N] bool) streams move. An
        empty ring's rows are its storage's first: it must not train on them."""
        if self._storage is None:
            raise ValueError("cannot sample from an empty HindsightReplayBuffer")
        rows = uniform_rows(self.sizes.unsqueeze(1), self.sampler, int(batch_size), active)

        def goal_uniforms(shape: torch.Size) -> torch.Tensor:
            return self.sampler.uniform(shape[-1], active, dtype=torch.float64)

        def take(name: str, at: torch.Tensor) -> torch.Tensor:
            return gather_rows(self._storage[name], at)

        return relabelled_columns(self, rows, take, columns, goal_uniforms)

    def sample_states(self, n: int, rng: np.random.Generator, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(observations [m, obs], achieved goals [m, g]) of m = min(n, size) distinct rows of ring
        `seed`: the states a SoRB graph is built on."""
        size = self._size[seed]
        if size == 0:
            raise ValueError("cannot sample states from an empty HindsightReplayBuffer")
        rows = torch.as_tensor(rng.choice(size, size=min(int(n), size), replace=False), device=self.device)
        return tuple(
            self._storage[k][seed].index_select(0, rows).cpu().numpy() for k in ("observation", "achieved")
        )

    # ------------------------------------------------------------------------------------- state
    def get_state(self, seed: int = 0) -> dict[str, Any]:
        """Ring `seed`: its filled rows in storage order (numpy), the write pointer, the counters and
        its sampler's counter (the reward function and layout are the algorithm's, rebuilt from its
        config)."""
        size, filled = self._size[seed], None
        if self._storage is not None and size:
            filled = {k: v[seed, :size].cpu().numpy().copy() for k, v in self._storage.items()}
        return {
            "capacity": self.capacity,
            "n_sampled_goal": self.n_sampled_goal,
            "goal_selection": self.goal_selection,
            "action_dim": self._action_dim,
            "ptr": self._ptr[seed],
            "size": size,
            "num_added": self._num_added[seed],
            "data": filled,
            "sampler": self.sampler.stream(seed).get_state(),
        }

    def set_state(self, state: Mapping[str, Any], seed: int = 0) -> None:
        """A one-seed `get_state` into ring `seed`. Another capacity is refused, and so is another
        action size in a stack, before anything changes."""
        if int(state["capacity"]) != self.capacity:
            raise ValueError(f"a checkpoint of capacity {state['capacity']} into a buffer of {self.capacity}")
        action_dim = state["action_dim"]
        if self.num_seeds > 1 and action_dim is not None and self._action_dim not in (None, int(action_dim)):
            raise ValueError(
                f"seed {self.seeds[seed]}: a snapshot of action size {action_dim} does not fit the "
                f"stack's {self._action_dim}"
            )
        self._ptr[seed], self._size[seed] = 0, 0
        self._num_added[seed] = int(state["num_added"])
        if action_dim is not None:
            self._allocate(int(action_dim), seed)
        if state.get("data"):
            size = int(state["size"])
            self._write_rows(
                seed, np.arange(size), {k: np.asarray(v)[:size] for k, v in state["data"].items()}
            )
            self._size[seed], self._ptr[seed] = size, int(state["ptr"])
        if state.get("sampler") is not None:
            self.sampler.stream(seed).set_state(state["sampler"])
        self._moved(seed)


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
    `HindsightReplayBuffer`). `uniform(shape)`:
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


def overwritten_prefix(pointer, start, length, capacity):
    """How many of an episode's first rows newer episodes have overwritten (numpy or torch): the ring
    writes on from `pointer`, so once it has come round to an episode (`start`, `length` rows) the rows
    from its start up to the pointer are another's. An episode's later rows outlive its earlier ones, so
    a goal from its sampled step on ("future", "final") is always its own; one from before ("episode")
    must start here."""
    behind = (pointer - start) % capacity
    return behind * (behind < length)
