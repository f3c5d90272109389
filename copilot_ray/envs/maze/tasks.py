"""Task sets: (start, goal) pairs drawn uniformly from the free configuration space."""

from __future__ import annotations

import numpy as np

from .agents import AgentGeometry
from .geometry import Obstacles

# Each split draws from its own seed stream, so train and test never share a pair for the same seed.
SPLITS = {"train": 0, "test": 1, "uniform": 2}


def split_rng(split: str, seed: int) -> np.random.Generator:
    if split not in SPLITS:
        raise ValueError(f"unknown task split {split!r}; valid: {', '.join(SPLITS)}")
    return np.random.default_rng(np.random.SeedSequence([int(seed), SPLITS[split]]))


def _free_configs(
    agent: AgentGeometry, obstacles: Obstacles, n: int, rng: np.random.Generator, margin: float
) -> np.ndarray:
    """n configurations uniform over {clearance >= margin} by rejection."""
    low, high = agent.bounds
    found: list[np.ndarray] = []
    count, tries = 0, 0
    while count < n:
        batch = low + (high - low) * rng.random((max(64, 4 * (n - count)), agent.config_dim))
        batch = batch.astype(np.float32).astype(np.float64)  # check exactly what the env will use
        ok = batch[agent.clearance(obstacles, batch) >= margin]
        found.append(ok)
        count += len(ok)
        tries += 1
        if tries > 1000 and count == 0:
            raise ValueError(f"no free configuration with clearance >= {margin} found in this layout")
    return np.concatenate(found)[:n]


def sample_task_pairs(
    agent: AgentGeometry,
    obstacles: Obstacles,
    n: int,
    rng: np.random.Generator,
    margin: float,
    min_separation: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(starts, goals) float32 [n, config_dim]: both at least `margin` from obstacles and the border,
    at least `min_separation` apart, and connected by a collision-free path where that can be checked."""
    starts_out: list[np.ndarray] = []
    goals_out: list[np.ndarray] = []
    count, rounds = 0, 0
    while count < n:
        rounds += 1
        if rounds > 200 and count == 0:
            raise ValueError("no (start, goal) pair in this layout is connected by a collision-free path")
        want = max(16, 2 * (n - count))
        starts = _free_configs(agent, obstacles, want, rng, margin)
        goals = _free_configs(agent, obstacles, want, rng, margin)
        keep = agent.distance(starts, goals) >= min_separation
        try:
            keep &= np.isfinite(agent.shortest_path_lengths(obstacles, starts, goals))
        except NotImplementedError:  # agents without an exact planner skip the reachability filter
            pass
        starts_out.append(starts[keep])
        goals_out.append(goals[keep])
        count += int(keep.sum())
    # Candidates are already float32-exact, so the env's observations equal the task exactly.
    starts = np.concatenate(starts_out)[:n].astype(np.float32)
    goals = np.concatenate(goals_out)[:n].astype(np.float32)
    return starts, goals
