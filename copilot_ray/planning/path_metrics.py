"""Planners scored as motion planners: the paper's Fig. 4b/4c figures, each also against RRT*.

Every method that produces paths is scored the same way on the env's held-out test tasks:

* **success**: a path whose every segment the env's own motion check finds collision-free and that ends
  within the success radius of the goal (a sub-goal tree's finest path ends at the goal itself);
* **length**: the path's length in the env's distance (``goal_distance``: wrapped angles, weighted like
  the env measures them), averaged over the successful paths;
* **collision checks**: what the method spent to get there (SGT-PG and CO-PILOT: every segment their
  planner's cost asked about in training; RRT*: its validity and motion callbacks).

Normalised by RRT* on the same tasks (``RRTReference``): success / RRT*'s success, the mean over tasks both
solved of length / RRT*'s length, and checks / RRT*'s total checks over those tasks. The reference is
computed once per (env, layout, tasks, time limit, seed) and cached on disk (``COPILOT_RAY_CACHE``,
default ``~/.cache/copilot_ray``), so the trials of a sweep share it; a file lock keeps two trials from
computing the same one twice. OMPL seeds its generator once per process: a cached reference is
reproducible only as a whole run of queries, which is how it is computed.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from copilot_ray import keys

REFERENCE_FORMAT = 1  # bump when what a cached reference means changes


@dataclass
class PathScores:
    """Per test task: whether the method's path succeeds and how long it is (inf where it fails)."""

    success: np.ndarray  # [N] bool
    length: np.ndarray  # [N] float


def score_paths(maze, paths: np.ndarray, goals: np.ndarray) -> PathScores:
    """Paths ``[N, P, d]`` (start first) on env ``maze`` (unwrapped): success and length per path."""
    paths = np.asarray(paths, np.float64)
    n, p, d = paths.shape
    a, b = paths[:, :-1].reshape(-1, d), paths[:, 1:].reshape(-1, d)
    free = ~np.asarray(maze.segments_collide(a, b), bool).reshape(n, p - 1).any(axis=1)
    at_goal = (
        np.asarray(maze.goal_distance(paths[:, -1], np.asarray(goals, np.float64))) <= maze.success_radius
    )
    success = free & at_goal
    length = np.asarray(maze.goal_distance(a, b), np.float64).reshape(n, p - 1).sum(axis=1)
    return PathScores(success, np.where(success, length, np.inf))


@dataclass
class RRTReference:
    """RRT* on the first ``len(solved)`` test tasks: solved, length (inf unsolved), checks per task."""

    solved: np.ndarray  # [N] bool
    length: np.ndarray  # [N] float
    checks: np.ndarray  # [N] int

    def save(self, path: Path) -> None:
        tmp = path.with_name(path.name + f".{os.getpid()}.tmp.npz")
        np.savez(tmp, solved=self.solved, length=self.length, checks=self.checks)
        tmp.replace(path)  # atomic: a reader never sees half a file

    @classmethod
    def load(cls, path: Path) -> RRTReference:
        with np.load(path) as f:
            return cls(f["solved"].astype(bool), f["length"].astype(np.float64), f["checks"].astype(np.int64))

    @classmethod
    def from_results(cls, results) -> RRTReference:
        """From ``RRTStarResult``s (``copilot_ray.planning.rrt_star``)."""
        return cls(
            np.array([r.solved for r in results], bool),
            np.array([r.length for r in results], np.float64),
            np.array([r.collision_checks for r in results], np.int64),
        )


def cache_dir() -> Path:
    return Path(os.environ.get("COPILOT_RAY_CACHE", Path.home() / ".cache" / "copilot_ray")) / "rrt_reference"


def reference_path(
    env_id: str, env_config: Mapping[str, Any], num_tasks: int, time_limit_s: float, seed: int
) -> Path:
    """Where the reference for these arguments is cached (a hash of all of them)."""
    what = {
        "format": REFERENCE_FORMAT,
        "env_id": env_id,
        "env_config": dict(env_config),
        "num_tasks": int(num_tasks),
        "time_limit_s": float(time_limit_s),
        "seed": int(seed),
    }
    digest = hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:16]
    return cache_dir() / f"{env_id}-{num_tasks}tasks-{time_limit_s:g}s-seed{seed}-{digest}.npz"


def plan_rrt_star(env, num_tasks: int, time_limit_s: float, seed: int, first: int = 0, progress=None):
    """``RRTStarResult``s on test tasks ``first .. num_tasks - 1`` of ``env`` (``progress(i, result)``
    after each)."""
    from copilot_ray.planning.rrt_star import rrt_star_for_env

    maze = env.unwrapped
    starts, goals = (x.astype(np.float64) for x in maze.tasks("test"))
    rrt = rrt_star_for_env(env, time_limit_s=time_limit_s, seed=seed)
    results = []
    for i in range(first, min(num_tasks, len(starts))):
        results.append(rrt.plan(starts[i], goals[i], maze.success_radius))
        if progress is not None:
            progress(i, results[-1])
    return results


def rrt_reference(
    env_id: str, env_config: Mapping[str, Any], num_tasks: int, time_limit_s: float, seed: int = 0
) -> RRTReference:
    """RRT* on the first ``num_tasks`` test tasks, from the cache or computed (then cached)."""
    from filelock import FileLock

    from copilot_ray.envs import make

    path = reference_path(env_id, env_config, num_tasks, time_limit_s, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(path) + ".lock"):
        if path.exists():
            return RRTReference.load(path)
        env = make(env_id, **dict(env_config))
        try:
            reference = RRTReference.from_results(plan_rrt_star(env, num_tasks, time_limit_s, seed))
        finally:
            env.close()
        reference.save(path)
        return reference


def path_metrics(
    scores: PathScores, collision_checks: int, reference: RRTReference | None = None
) -> dict[str, float]:
    """The ``paths/*`` metrics (``copilot_ray.keys``) of one evaluation; the ``*_vs_rrt`` ones only with a
    reference (on the same first tasks). NaN where a figure is undefined (no successful path)."""
    n = len(scores.success)
    success = scores.success
    out = {
        keys.PATH_TASKS: float(n),
        keys.PATH_SUCCESS: float(success.mean()) if n else float("nan"),
        keys.PATH_LENGTH: float(scores.length[success].mean()) if success.any() else float("nan"),
        keys.PATH_COLLISION_CHECKS: float(collision_checks),
    }
    if reference is None:
        return out
    if len(reference.solved) < n:
        raise ValueError(f"the RRT* reference covers {len(reference.solved)} tasks, {n} were scored")
    solved, rrt_length = reference.solved[:n], reference.length[:n]
    both = success & solved
    out[keys.PATH_SUCCESS_VS_RRT] = float(success.mean() / solved.mean()) if solved.any() else float("nan")
    out[keys.PATH_LENGTH_VS_RRT] = (
        float(np.mean(scores.length[both] / rrt_length[both])) if both.any() else float("nan")
    )
    rrt_checks = int(reference.checks[:n].sum())
    out[keys.PATH_CHECKS_VS_RRT] = float(collision_checks / rrt_checks) if rrt_checks else float("nan")
    return out


class CountedChecks:
    """A batched ``segments_collide(a, b)`` that counts the segments it was asked about."""

    def __init__(self, check):
        self.check, self.count = check, 0

    def __call__(self, a, b):
        self.count += len(a)
        return self.check(a, b)
