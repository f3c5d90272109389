"""Task sets: (start, goal) pairs drawn uniformly from the free configuration space."""

from __future__ import annotations

import numpy as np

from copilot_ray.envs.task_sets import SPLIT_STREAMS as SPLITS
from copilot_ray.envs.task_sets import split_rng

from .agents import AgentGeometry
from .geometry import Obstacles
from .layouts import BodyDoesNotFitError

__all__ = ["SPLITS", "check_body_fits", "sample_task_pairs", "split_rng"]


FIT_SAMPLES = 50_000  # configurations tried before a body is declared not to fit a layout
_FITS: dict[tuple, bool] = {}  # (agent, layout, margin) -> checked once per process


def check_body_fits(agent: AgentGeometry, obstacles: Obstacles, margin: float, layout: str, grid_key) -> None:
    """Raises BodyDoesNotFitError unless some configuration of `agent` has clearance >= `margin` (tasks
    need one; rejection sampling would otherwise search forever). Uniform samples in growing batches,
    up to FIT_SAMPLES; an ordinary layout answers with its first batch. Cached per process.

    Every agent's (x, y) (the first two dims) is a point of its body, so the body's clearance is at most
    that point's: the cheap point clearance rules most samples out before the body's is computed."""
    key = (type(agent).__name__, agent.body, layout, grid_key, float(margin))
    if _FITS.get(key):
        return
    rng = np.random.default_rng(0)
    low, high = agent.bounds
    tried, best, batch = 0, -np.inf, 256
    while tried < FIT_SAMPLES:
        configs = low + (high - low) * rng.random((batch, agent.config_dim))
        point = obstacles.clearance(configs[:, :2])
        candidates = configs[point >= margin]
        clearance = agent.clearance(obstacles, candidates) if len(candidates) else point
        best = max(best, float(clearance.max()))
        if best >= margin:
            _FITS[key] = True
            return
        tried += batch
        batch = min(4 * batch, FIT_SAMPLES - tried) or 1
    raise BodyDoesNotFitError(
        layout,
        f"the maze-{agent.name} agent's body ({agent.body}) fits nowhere in this layout with the clearance "
        f"tasks need (>= {margin:g}, the success radius): the largest clearance among {tried:,} random "
        f"configurations was {best:.4f}; widen its free cells or use a smaller agent",
    )


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
