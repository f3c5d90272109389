"""Two-level episodes of N goal envs in lockstep, one batched call per level and step: the high level
proposes an offset every c steps, the low level acts on the absolute sub-goal achieved + offset, which
the goal transition h keeps fixed until the next proposal. Training and evaluation run the same code.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from copilot_ray.algorithms.hrl.hierarchy import SubgoalBox

Policy = Callable[[np.ndarray], np.ndarray]  # flat inputs [n, D] -> actions [n, A] in [-1, 1]
Compose = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Episode:
    """One env's episode: T steps, S = ceil(T / c) segments (segment s covers steps s*c .. s*c + c - 1)."""

    goal: np.ndarray  # [g] the task's goal
    observations: np.ndarray  # [T + 1, o]
    achieved: np.ndarray  # [T + 1, g]
    actions: np.ndarray  # [T, A] the low level's
    rewards: np.ndarray  # [T] the goal env's
    collisions: np.ndarray  # [T]
    terminated: bool  # the goal was reached (the env ended the episode)
    high_actions: np.ndarray  # [S, g] the high level's, in [-1, 1]
    subgoals: np.ndarray  # [S, g] absolute sub-goals: achieved at the proposal + offset

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def success(self) -> bool:
        """Reached the goal with no collision (as every evaluation here counts it)."""
        return bool(self.terminated and not self.collisions.any())


def run_episodes(
    envs: Sequence,
    starts: np.ndarray,
    goals: np.ndarray,
    high: Policy,
    low: Policy,
    box: SubgoalBox,
    c: int,
    tau_max: int,
    compose: Compose,
) -> list[Episode]:
    """One episode of at most `tau_max` steps per env, env i from starts[i] towards goals[i]."""
    n = len(starts)
    obs, ach = [], []
    for env, start, goal in zip(envs[:n], starts, goals, strict=True):
        o, _ = env.reset(options={"start": start, "goal": goal})
        obs.append(o["observation"])
        ach.append(o["achieved_goal"])
    trace_obs = [[o] for o in obs]
    trace_ach = [[a] for a in ach]
    trace_act, trace_rew, trace_col = ([[] for _ in range(n)] for _ in range(3))
    trace_high, trace_sub = [[] for _ in range(n)], [[] for _ in range(n)]
    obs, ach = np.stack(obs), np.stack(ach)
    goals = np.asarray(goals, np.float32)
    subgoal = np.zeros_like(ach)
    terminated = np.zeros(n, bool)
    active = np.ones(n, bool)
    for t in range(int(tau_max)):
        ids = np.flatnonzero(active)
        if len(ids) == 0:
            break
        if t % c == 0:  # a new proposal: s + g, carried unchanged by h until the next one
            a_high = np.asarray(high(compose(obs[ids], goals[ids], ach[ids])), np.float32)
            subgoal[ids] = ach[ids] + box.offset(a_high)
            for j, i in enumerate(ids):
                trace_high[i].append(a_high[j])
                trace_sub[i].append(subgoal[i].copy())
        actions = np.asarray(low(compose(obs[ids], subgoal[ids], ach[ids])), np.float32)
        for j, i in enumerate(ids):
            o, r, term, trunc, info = envs[i].step(actions[j])
            obs[i], ach[i] = o["observation"], o["achieved_goal"]
            trace_obs[i].append(obs[i].copy())
            trace_ach[i].append(ach[i].copy())
            trace_act[i].append(actions[j])
            trace_rew[i].append(float(r))
            trace_col[i].append(bool(info.get("collision", False)))
            if term or trunc:
                active[i] = False
                terminated[i] = bool(term)
    return [
        Episode(
            goal=goals[i],
            observations=np.asarray(trace_obs[i], np.float32),
            achieved=np.asarray(trace_ach[i], np.float32),
            actions=np.asarray(trace_act[i], np.float32).reshape(len(trace_act[i]), -1),
            rewards=np.asarray(trace_rew[i], np.float32),
            collisions=np.asarray(trace_col[i], bool),
            terminated=bool(terminated[i]),
            high_actions=np.asarray(trace_high[i], np.float32),
            subgoals=np.asarray(trace_sub[i], np.float32),
        )
        for i in range(n)
    ]
