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

from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np
import torch

from copilot_ray.algorithms.gc_sac.device_replay import SAMPLE_STREAM, uniform_rows
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
    """A `HindsightReplayBuffer` on `device` (module docstring); `reward_fn` is a `TorchRewardFn`."""

    def __init__(
        self,
        capacity: int,
        layout: GoalLayout,
        reward_fn: TorchRewardFn,
        n_sampled_goal: int = 4,
        goal_selection: str = "future",
        device: torch.device | str = "cpu",
        seed: int = 0,
    ):
        super().__init__(capacity, layout, reward_fn, n_sampled_goal, goal_selection)
        self.device = torch.device(device)
        self.sampler = PhiloxStreams([int(seed)], SAMPLE_STREAM, self.device)
        self._size_t = torch.zeros((), dtype=torch.int64, device=self.device)
        self._ptr_t = torch.zeros((), dtype=torch.int64, device=self.device)  # the ring's, for "episode"
        self.storage_version = 0

    # ------------------------------------------------------------------------- storage on the device
    def _allocate(self, action_dim: int) -> None:
        self._action_dim = action_dim
        self._data = hindsight_storage((self.capacity,), self.layout, action_dim, self.device)
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
        self._ptr_t.fill_(self._ptr)
        return added

    def get_state(self) -> dict[str, Any]:
        """`HindsightReplayBuffer.get_state`, plus the sampler's counter."""
        return {**super().get_state(), "sampler": self.sampler.get_state()}

    def set_state(self, state: Mapping[str, object]) -> None:
        """`HindsightReplayBuffer.set_state` (either buffer's state), then the device's copy of the size
        (and the sampler's counter, where the snapshot has one)."""
        super().set_state(state)
        self._size_t.fill_(self._size)
        self._ptr_t.fill_(self._ptr)
        if state.get("sampler") is not None:
            self.sampler.set_state(state["sampler"])

    def write_pointers(self) -> torch.Tensor:
        """The ring's next row, on the device (a captured step reads it as the buffer fills)."""
        return self._ptr_t

    # ------------------------------------------------------------------------------------ sampling
    def _take(self, name: str, rows: torch.Tensor) -> torch.Tensor:
        """Column `name` at storage rows `rows` ([B])."""
        return self._data[name].index_select(0, rows)

    def sample(self, batch_size: int, columns: Iterable[str] = TRAIN_COLUMNS) -> dict[str, torch.Tensor]:
        """`batch_size` uniform transitions, the first her_ratio of them with hindsight goals, as the
        agent's flat columns: [1, batch_size, ...] device tensors (one seed, as every device buffer
        samples a leading seed axis); no host sync."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty DeviceHindsightBuffer")
        rows = uniform_rows(self._size_t, self.sampler, int(batch_size))[0]

        def goal_uniforms(shape: torch.Size) -> torch.Tensor:
            return self.sampler.uniform(shape[-1], dtype=torch.float64)[0]

        batch = relabelled_columns(self, rows, self._take, columns, goal_uniforms)
        return {k: v.unsqueeze(0) for k, v in batch.items()}


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
    `DeviceHindsightBuffer`, or `seed_replay.StackedHindsightBuffer` for its seeds). `uniform(shape)`:
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
