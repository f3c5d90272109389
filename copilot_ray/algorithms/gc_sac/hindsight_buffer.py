"""Hindsight experience replay (HER) as a replay buffer, as Stable-Baselines3 does it: the algorithm
stays SAC, only the transitions it learns from change.

Transitions are stored whole episodes at a time with their raw parts (observation, achieved goal,
desired goal, collision flag) and the position of each step in its episode. `sample` draws uniform
rows; a share `n_sampled_goal / (n_sampled_goal + 1)` of them (SB3's `her_ratio`) gets a new goal
achieved later in the same episode (`future`), at its end (`final`) or anywhere in it (`episode`),
and their reward and termination are recomputed in one batch by `reward_fn` (the goal env's
`compute_reward` / `compute_terminated` under the traversal rules). The agent's flat input is put
together at sampling time (`GoalLayout.compose`), so the relabelled goal also enters the
goal - achieved part of `agent_input="state_goal_delta"`.

A sample has the `FlatTransitionBuffer` columns (obs, new_obs, actions, rewards, terminateds), so the
same `update_from_buffer` drives the learner from either buffer.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from copilot_ray.algorithms.gc_sac.replay_buffer import (
    ACTIONS,
    NEXT_OBS,
    OBS,
    REWARDS,
    TERMINATEDS,
    TRAIN_COLUMNS,
    TRUNCATEDS,
)
from copilot_ray.envs.goal_observation import flat_observation

GOAL_SELECTIONS = ("future", "final", "episode")
# (next achieved goals [n, g], goals [n, g], collisions [n]) -> (rewards [n], terminateds [n])
RewardFn = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


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


class HindsightReplayBuffer:
    """A ring buffer of whole episodes that relabels goals when sampled (module docstring).

    Args:
        capacity: transitions kept; the oldest are overwritten first (an episode's later transitions
            are always newer, so a `future` goal never points at an overwritten row).
        layout: where observation and goal sit in the flat input.
        reward_fn: batched (rewards, terminateds) for relabelled goals.
        n_sampled_goal: relabelled goals per real one (SB3's default 4: 80 % of a batch relabelled);
            0 samples the stored transitions only.
        goal_selection: "future" (SB3's default), "final" or "episode".
    """

    def __init__(
        self,
        capacity: int,
        layout: GoalLayout,
        reward_fn: RewardFn,
        n_sampled_goal: int = 4,
        goal_selection: str = "future",
    ):
        if int(capacity) <= 0:
            raise ValueError(f"capacity must be > 0, got {capacity}")
        if int(n_sampled_goal) < 0:
            raise ValueError(f"n_sampled_goal must be >= 0, got {n_sampled_goal}")
        if goal_selection not in GOAL_SELECTIONS:
            raise ValueError(
                f"goal_selection={goal_selection!r} is invalid: use one of {list(GOAL_SELECTIONS)}"
            )
        self.capacity = int(capacity)
        self.layout = layout
        self.reward_fn = reward_fn
        self.n_sampled_goal = int(n_sampled_goal)
        self.her_ratio = 1.0 - 1.0 / (self.n_sampled_goal + 1)
        self.goal_selection = goal_selection
        self._data: dict[str, np.ndarray] | None = None
        self._action_dim: int | None = None
        self._ptr = 0
        self._size = 0
        self._num_added = 0

    def _allocate(self, action_dim: int) -> None:
        widths = {"obs": self.layout.obs_dim, "goal": self.layout.goal_dim, "action": action_dim}
        self._action_dim = action_dim
        self._data = {
            name: np.zeros((self.capacity,) if w is None else (self.capacity, widths[w]), dtype)
            for name, (w, dtype) in STORED_COLUMNS.items()
        }

    def _write_rows(self, rows: np.ndarray, cols: Mapping[str, np.ndarray]) -> None:
        """Stores `cols` (column -> values, one per row) at storage rows `rows`."""
        for name, values in cols.items():
            self._data[name][rows] = values

    def _filled(self) -> dict[str, np.ndarray]:
        """Copies of the filled rows, storage order."""
        return {k: v[: self._size].copy() for k, v in self._data.items()}

    def __len__(self) -> int:
        return self._size

    @property
    def num_added(self) -> int:
        return self._num_added

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
    ) -> int:
        """One episode (or its first T steps): T + 1 raw observations and achieved goals, its goal,
        T actions, rewards and collision flags (and goal-independent dense rewards, default 0);
        `terminated`: whether its last step ended it. Returns T."""
        t = len(actions)
        if t == 0:
            return 0
        if len(observations) != t + 1 or len(achieved) != t + 1:
            raise ValueError(f"an episode of {t} steps needs {t + 1} observations and achieved goals")
        actions = np.asarray(actions, np.float32).reshape(t, -1)
        if self._data is None:
            self._allocate(actions.shape[1])
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
            "episode_start": np.full(t, self._num_added, np.int64),
            "episode_length": np.full(t, t, np.int64),
            "step": np.arange(t),
        }
        self._write_rows((self._ptr + np.arange(t)) % self.capacity, cols)
        self._ptr = (self._ptr + t) % self.capacity
        self._size = min(self._size + t, self.capacity)
        self._num_added += t
        return t

    def add_episodes(self, episodes: Iterable[Any]) -> int:
        """RLlib `SingleAgentEpisode`s of the traversal env, whose infos carry `achieved_goal` (reset
        and every step) and `collision` (every step). Returns the transitions added."""
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
            )
        return added

    # ---------------------------------------------------------------------------------- sampling
    def _hindsight_goals(self, rows: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        d = self._data
        start, length, step = d["episode_start"][rows], d["episode_length"][rows], d["step"][rows]
        if self.goal_selection == "future":
            offset = rng.integers(step, length)  # SB3: this step or a later one
        elif self.goal_selection == "final":
            offset = length - 1
        else:  # anywhere in it still its own
            offset = rng.integers(overwritten_prefix(self._ptr, start, length, self.capacity), length)
        return d["next_achieved"][(start + offset) % self.capacity]

    def sample(
        self, batch_size: int, rng: np.random.Generator, columns: Iterable[str] = TRAIN_COLUMNS
    ) -> dict[str, np.ndarray]:
        """`batch_size` uniform transitions, the first her_ratio of them with hindsight goals, as the
        agent's flat columns (obs, new_obs, actions, rewards, terminateds, truncateds)."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty HindsightReplayBuffer")
        d = self._data
        rows = rng.integers(0, self._size, size=int(batch_size))
        goals = d["goal"][rows]
        rewards = d[REWARDS][rows].copy()
        terminateds = d[TERMINATEDS][rows].copy()
        n_her = int(round(self.her_ratio * len(rows)))
        if n_her:
            her = rows[:n_her]
            goals[:n_her] = self._hindsight_goals(her, rng)
            r, t = self.reward_fn(d["next_achieved"][her], goals[:n_her], d["collision"][her])
            rewards[:n_her], terminateds[:n_her] = r + d["dense"][her], t
        out = {
            OBS: self.layout.compose(d["observation"][rows], goals, d["achieved"][rows]),
            NEXT_OBS: self.layout.compose(d["next_observation"][rows], goals, d["next_achieved"][rows]),
            ACTIONS: d[ACTIONS][rows],
            REWARDS: rewards,
            TERMINATEDS: terminateds,
            TRUNCATEDS: np.zeros(len(rows), bool),
        }
        return {k: out[k] for k in columns}

    def sample_states(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(observations [m, obs], achieved goals [m, g]) of m = min(n, size) distinct stored rows:
        the states a SoRB graph is built on."""
        if self._size == 0:
            raise ValueError("cannot sample states from an empty HindsightReplayBuffer")
        rows = rng.choice(self._size, size=min(int(n), self._size), replace=False)
        return self._rows_as_numpy("observation", rows), self._rows_as_numpy("achieved", rows)

    def _rows_as_numpy(self, name: str, rows: np.ndarray) -> np.ndarray:
        return self._data[name][rows].copy()

    # ------------------------------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """Filled rows in storage order, the write pointer and the counters (the reward function and
        layout are the algorithm's, rebuilt from its config)."""
        filled = None
        if self._data is not None and self._size:
            filled = self._filled()
        return {
            "capacity": self.capacity,
            "n_sampled_goal": self.n_sampled_goal,
            "goal_selection": self.goal_selection,
            "action_dim": self._action_dim,
            "ptr": self._ptr,
            "size": self._size,
            "num_added": self._num_added,
            "data": filled,
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        if int(state["capacity"]) != self.capacity:
            raise ValueError(f"a checkpoint of capacity {state['capacity']} into a buffer of {self.capacity}")
        self._data, self._ptr, self._size = None, 0, 0
        self._num_added = int(state["num_added"])
        if state["action_dim"] is not None:
            self._allocate(int(state["action_dim"]))
        if state.get("data"):
            size = int(state["size"])
            self._write_rows(np.arange(size), {k: np.asarray(v)[:size] for k, v in state["data"].items()})
            self._size, self._ptr = size, int(state["ptr"])


def overwritten_prefix(pointer, start, length, capacity):
    """How many of an episode's first rows newer episodes have overwritten (numpy or torch): the ring
    writes on from `pointer`, so once it has come round to an episode (`start`, `length` rows) the rows
    from its start up to the pointer are another's. An episode's later rows outlive its earlier ones, so
    a goal from its sampled step on ("future", "final") is always its own; one from before ("episode")
    must start here."""
    behind = (pointer - start) % capacity
    return behind * (behind < length)
