"""Episodes -> replay rows for each level.

Low level: one transition per env step, conditioned on its segment's absolute sub-goal (the next
observation too: the sub-goal that was pursued, not the next proposal). `dense`: HIRO's reward
-||s + g - s'||, never terminal; `sparse`: the goal env's reward for reaching the sub-goal
(`compute_reward` / `compute_terminated` with the sub-goal as the desired goal), terminal there.

High level: one transition per segment, (s_t, g, action, reward_scale x sum of the env's rewards over
the segment, s_{t+c}), terminal when the episode ended at the goal, with the segment's low-level
observations, achieved goals and actions for the off-policy correction.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from copilot_ray.algorithms.gc_sac.replay_buffer import ACTIONS, NEXT_OBS, OBS, REWARDS, TERMINATEDS
from copilot_ray.algorithms.hrl.hierarchy import dense_low_reward
from copilot_ray.algorithms.hrl.rollout import Compose, Episode

# (achieved [n, g], desired [n, g]) -> values [n]: the goal env's compute_reward / compute_terminated
GoalFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def segment_bounds(length: int, c: int) -> list[tuple[int, int]]:
    """[(first step, one past the last step)] of each segment of an episode of `length` steps."""
    return [(s, min(s + c, length)) for s in range(0, length, c)]


def low_level_rows(
    episodes: Sequence[Episode],
    c: int,
    compose: Compose,
    low_reward: str,
    reward_fn: GoalFn,
    reached_fn: GoalFn,
) -> dict[str, np.ndarray]:
    """The low level's transitions of `episodes` (FlatTransitionBuffer columns)."""
    parts = []
    for ep in episodes:
        t = len(ep)
        if t == 0:
            continue
        target = np.repeat(ep.subgoals, c, axis=0)[:t]  # [T, g]: each step's segment's sub-goal
        nxt = ep.achieved[1:]
        if low_reward == "dense":
            reward = dense_low_reward(ep.achieved[:-1], target - ep.achieved[:-1], nxt)
            done = np.zeros(t, bool)
        else:
            reward = np.asarray(reward_fn(nxt, target), np.float32)
            done = np.asarray(reached_fn(nxt, target), bool)
        parts.append(
            {
                OBS: compose(ep.observations[:-1], target, ep.achieved[:-1]),
                NEXT_OBS: compose(ep.observations[1:], target, nxt),
                ACTIONS: ep.actions,
                REWARDS: reward.astype(np.float32),
                TERMINATEDS: done,
            }
        )
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts else {}


def high_level_rows(
    episodes: Sequence[Episode], c: int, compose: Compose, reward_scale: float
) -> dict[str, np.ndarray]:
    """The high level's transitions of `episodes` (SegmentReplayBuffer columns)."""
    rows: dict[str, list] = {
        k: []
        for k in (OBS, NEXT_OBS, ACTIONS, REWARDS, TERMINATEDS, "start", "end")
        + ("seg_obs", "seg_achieved", "seg_actions", "seg_mask")
    }
    for ep in episodes:
        bounds = segment_bounds(len(ep), c)
        for s, (a, b) in enumerate(bounds):
            n = b - a
            pad = ((0, c - n), (0, 0))
            rows[OBS].append(compose(ep.observations[a], ep.goal, ep.achieved[a]))
            rows[NEXT_OBS].append(compose(ep.observations[b], ep.goal, ep.achieved[b]))
            rows[ACTIONS].append(ep.high_actions[s])
            rows[REWARDS].append(reward_scale * float(ep.rewards[a:b].sum()))
            rows[TERMINATEDS].append(ep.terminated and s == len(bounds) - 1)
            rows["start"].append(ep.achieved[a])
            rows["end"].append(ep.achieved[b])
            rows["seg_obs"].append(np.pad(ep.observations[a:b], pad))
            rows["seg_achieved"].append(np.pad(ep.achieved[a:b], pad))
            rows["seg_actions"].append(np.pad(ep.actions[a:b], pad))
            rows["seg_mask"].append(np.arange(c) < n)
    if not rows[OBS]:
        return {}
    out = {k: np.stack(v) for k, v in rows.items()}
    out[REWARDS] = out[REWARDS].astype(np.float32)
    out[TERMINATEDS] = out[TERMINATEDS].astype(bool)
    return out


def subgoals_reached(episodes: Sequence[Episode], c: int, reached_fn: GoalFn) -> np.ndarray:
    """bool per segment: whether the achieved goal at its end is within the env's success radius of
    its sub-goal (how well the low level follows the high level)."""
    ends, subgoals = [], []
    for ep in episodes:
        for s, (_, b) in enumerate(segment_bounds(len(ep), c)):
            ends.append(ep.achieved[b])
            subgoals.append(ep.subgoals[s])
    if not ends:
        return np.zeros(0, bool)
    return np.asarray(reached_fn(np.stack(ends), np.stack(subgoals)), bool)
