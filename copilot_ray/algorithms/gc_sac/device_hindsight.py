"""HER's relabelling buffer with its rows on the learner's device, relabelled and sampled there.

`DeviceHindsightBuffer` is a `HindsightReplayBuffer` (same episodes in, same state out: either restores
the other's checkpoint) whose columns are torch tensors on `device`. `sample(batch_size)` does
everything the numpy buffer's does, on the device and without a host synchronisation, so it can run
inside the fused SAC step and its CUDA graph: uniform rows (`device_replay.uniform_rows`), hindsight
goals for the first her_ratio of them (`future`, `final` or `episode`), their rewards and terminations
from a torch `reward_fn`, the dense reward added back, the agent's flat inputs composed for the new
goals. It draws from torch's generator of the device (no numpy rng).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

import numpy as np
import torch

from copilot_ray.algorithms.gc_sac.device_replay import uniform_rows
from copilot_ray.algorithms.gc_sac.hindsight_buffer import STORED_COLUMNS, GoalLayout, HindsightReplayBuffer
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
_TORCH_DTYPES = {np.float32: torch.float32, bool: torch.bool, np.int64: torch.int64}


class DeviceHindsightBuffer(HindsightReplayBuffer):
    """A `HindsightReplayBuffer` on `device` (module docstring); `reward_fn` is a `TorchRewardFn`."""

    def __init__(
        self,
        capacity: int,
        layout: GoalLayout,
        reward_fn: TorchRewardFn,
        n_sampled_goal: int = 4,
        goal_selection: str = "future",
        device: torch.device | str = "cpu",
    ):
        super().__init__(capacity, layout, reward_fn, n_sampled_goal, goal_selection)
        self.device = torch.device(device)
        self._size_t = torch.zeros((), dtype=torch.int64, device=self.device)
        self.storage_version = 0

    # ------------------------------------------------------------------------- storage on the device
    def _allocate(self, action_dim: int) -> None:
        widths = {"obs": self.layout.obs_dim, "goal": self.layout.goal_dim, "action": action_dim}
        self._action_dim = action_dim
        self._data = {
            name: torch.zeros(
                (self.capacity,) if w is None else (self.capacity, widths[w]),
                dtype=_TORCH_DTYPES[dtype],
                device=self.device,
            )
            for name, (w, dtype) in STORED_COLUMNS.items()
        }
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

    def add_episode(self, *args, **kwargs) -> int:
        """`HindsightReplayBuffer.add_episode`, then the device's copy of the size."""
        added = super().add_episode(*args, **kwargs)
        self._size_t.fill_(self._size)
        return added

    def set_state(self, state: Mapping[str, object]) -> None:
        """`HindsightReplayBuffer.set_state` (either buffer's state), then the device's copy of the size."""
        super().set_state(state)
        self._size_t.fill_(self._size)

    # ------------------------------------------------------------------------------------ sampling
    def _device_hindsight_goals(self, rows: torch.Tensor) -> torch.Tensor:
        d = self._data
        start, length, step = (
            d[k].index_select(0, rows) for k in ("episode_start", "episode_length", "step")
        )
        if self.goal_selection == "final":
            offset = length - 1
        else:
            low = step if self.goal_selection == "future" else torch.zeros_like(step)
            u = torch.rand(rows.shape[0], device=self.device, dtype=torch.float64)
            offset = torch.minimum(low + (u * (length - low)).long(), length - 1)  # uniform in [low, length)
        return d["next_achieved"].index_select(0, (start + offset) % self.capacity)

    def _compose(self, observation: torch.Tensor, goal: torch.Tensor, achieved: torch.Tensor) -> torch.Tensor:
        parts = [observation, goal, goal - achieved] if self.layout.with_delta else [observation, goal]
        return torch.cat(parts, dim=-1)

    def sample(self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions, the first her_ratio of them with hindsight goals, as the
        agent's flat columns (device tensors; no host sync)."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty DeviceHindsightBuffer")
        d = self._data
        rows = uniform_rows(self._size_t, int(batch_size), self.device)

        def at(name: str, which: torch.Tensor = rows) -> torch.Tensor:
            return d[name].index_select(0, which)

        goals, rewards, terminateds = at("goal"), at(REWARDS), at(TERMINATEDS)
        n_her = int(round(self.her_ratio * len(rows)))
        if n_her:
            her = rows[:n_her]
            new_goals = self._device_hindsight_goals(her)
            r, t = self.reward_fn(at("next_achieved", her), new_goals, at("collision", her))
            goals = torch.cat([new_goals, goals[n_her:]])
            rewards = torch.cat([(r + at("dense", her)).to(torch.float32), rewards[n_her:]])
            terminateds = torch.cat([t.to(torch.bool), terminateds[n_her:]])
        out = {
            OBS: self._compose(at("observation"), goals, at("achieved")),
            NEXT_OBS: self._compose(at("next_observation"), goals, at("next_achieved")),
            ACTIONS: at(ACTIONS),
            REWARDS: rewards,
            TERMINATEDS: terminateds,
            TRUNCATEDS: torch.zeros(len(rows), dtype=torch.bool, device=self.device),
        }
        return {k: out[k] for k in columns}
