"""Sub-goal trees cut from RRT* paths: the classical-planner curriculum (`algorithm: rrt_curriculum`).

A task's tree of depth K is its RRT* path (OMPL, on the env's own validity and motion checks) resampled
at 2^K + 1 points of equal path length, the first the task's start and the last its goal. Layer k of
that tree (every 2^(K-k)-th point) is then the path cut into 2^k pieces of equal length: a coarse layer
joins points of the path by straight shortcuts, which may cross walls, exactly as CO-PILOT's learned
trees may. No learned planner: the curriculum differs from CO-PILOT only in where its trees come from.

Each task is planned once and its tree kept (train tasks when first drawn, validation and test tasks at
the first evaluation); every validity and motion check RRT* makes is counted (a privilege, as CO-PILOT's
planner's checks are). A task RRT* does not solve in its time gets the straight line from start to goal,
cut the same way, and is counted as unsolved.

    trees = RRTTrees(env, depth=5, time_limit_s=0.5, seed=0)
    trees.sample(starts, goals)        # [N, 2^K + 1, d]; the planner interface evaluation takes

`RRTTreeCurriculum` is the same trees as a curriculum the agent holds (`planning.curriculum`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from copilot_ray import keys

from .subgoal_tree import check_depth


def cut_path(
    path: np.ndarray,
    pieces: int,
    distance: Callable[[np.ndarray, np.ndarray], np.ndarray],
    angle_dims: Sequence[int] = (),
) -> np.ndarray:
    """`pieces + 1` points [pieces + 1, d] along the polyline `path` [P, d] (P >= 1), equally spaced in
    path length under `distance` (batched: [N, d], [N, d] -> [N]); the first and last are the path's.
    Angles (`angle_dims`) are interpolated the short way round, as the envs move through them."""
    path = np.asarray(path, np.float64)
    if path.ndim != 2 or len(path) == 0:
        raise ValueError(f"a path is [P >= 1, d] points, got shape {path.shape}")
    if pieces < 1:
        raise ValueError(f"pieces must be >= 1, got {pieces!r}")
    if len(path) == 1:
        return np.repeat(path, pieces + 1, axis=0)
    steps = np.diff(path, axis=0)
    for i in angle_dims:
        steps[:, i] = (steps[:, i] + np.pi) % (2 * np.pi) - np.pi
    lengths = np.asarray(distance(path[:-1], path[1:]), np.float64)
    ends = np.concatenate([[0.0], np.cumsum(lengths)])
    targets = np.linspace(0.0, ends[-1], pieces + 1)
    # The segment each target lies on (a zero-length segment is never chosen unless all are).
    seg = np.clip(np.searchsorted(ends, targets, side="right") - 1, 0, len(lengths) - 1)
    frac = np.where(lengths[seg] > 0, (targets - ends[seg]) / np.where(lengths[seg] > 0, lengths[seg], 1), 0)
    points = path[seg] + np.clip(frac, 0.0, 1.0)[:, None] * steps[seg]
    points[0], points[-1] = path[0], path[-1]
    return points


class RRTTrees:
    """Trees from RRT* paths for the tasks asked about, each planned once and kept (see the module
    docstring). `checks`: every validity and motion check RRT* made; `solved` / `unsolved`: tasks."""

    def __init__(self, env, depth: int, time_limit_s: float, seed: int = 0):
        from .rrt_star import rrt_star_for_env

        self.depth = check_depth(depth)
        self.maze = env.unwrapped
        geometry = self.maze.agent_geometry
        self._angle_dims = tuple(geometry.angle_dims)
        self._rrt = rrt_star_for_env(env, time_limit_s=time_limit_s, seed=seed)
        self._kept: dict[bytes, np.ndarray] = {}
        self.checks = 0
        self.solved = 0
        self.unsolved = 0

    @staticmethod
    def _key(start: np.ndarray, goal: np.ndarray) -> bytes:
        return np.concatenate([start, goal]).astype(np.float32).tobytes()

    def _plan(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        result = self._rrt.plan(start.astype(np.float64), goal.astype(np.float64), self.maze.success_radius)
        self.checks += result.collision_checks
        if result.solved:
            self.solved += 1
            # The path ends within the goal radius; the tree ends at the goal itself (the traversal's
            # last sub-goal is the task's).
            path = np.concatenate([result.path, goal[None].astype(np.float64)])
        else:
            self.unsolved += 1
            path = np.stack([start, goal]).astype(np.float64)
        return cut_path(path, 2**self.depth, self.maze.goal_distance, self._angle_dims).astype(np.float32)

    def sample(self, starts: np.ndarray, goals: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Trees [N, 2^K + 1, d] of the tasks (starts [N, d], goals [N, d]); planned where not kept yet.
        `deterministic` is the planner interface's: these trees have no noise."""
        out = []
        for start, goal in zip(np.asarray(starts), np.asarray(goals), strict=True):
            key = self._key(start, goal)
            if key not in self._kept:
                self._kept[key] = self._plan(start, goal)
            out.append(self._kept[key])
        return np.stack(out)

    # ---------------------------------------------------------------------------------- checkpoint
    def state_dict(self) -> dict[str, Any]:
        keys = list(self._kept)
        return {
            "tasks": np.frombuffer(b"".join(keys), np.float32).reshape(len(keys), -1) if keys else None,
            "trees": np.stack([self._kept[k] for k in keys]) if keys else None,
            "checks": self.checks,
            "solved": self.solved,
            "unsolved": self.unsolved,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self._kept = {}
        if state["tasks"] is not None:
            for task, tree in zip(np.asarray(state["tasks"]), np.asarray(state["trees"]), strict=True):
                self._kept[task.astype(np.float32).tobytes()] = tree
        self.checks, self.solved, self.unsolved = (int(state[k]) for k in ("checks", "solved", "unsolved"))


class RRTTreeCurriculum:
    """The classical-planner curriculum (`planning.curriculum.Curriculum`): each drawn task's RRT* tree,
    the same trees for every repetition; nothing learned. `planner` (the RRTTrees) is also what
    evaluation follows."""

    state_key = "rrt_curriculum"

    def __init__(self, env, depth: int, repetitions: int, time_limit_s: float, seed: int = 0):
        self.depth, self.repetitions = check_depth(depth), int(repetitions)
        self.planner = RRTTrees(env, depth, time_limit_s, seed=seed)

    def prepare(self, iteration: int, rng, heartbeat=None) -> dict[str, float]:
        return {}

    def tasks_to_draw(self, traversed: int) -> int:
        return traversed

    def trees(self, starts, goals, traversed: int, rng) -> tuple[np.ndarray, dict[str, float]]:
        """The traversed tasks' trees (RRT* plans a task the first time it is drawn)."""
        return self.planner.sample(starts[:traversed], goals[:traversed]), {}

    def learn(self, subtasks, rng) -> dict[str, float]:
        return {}

    def summary(self) -> dict[str, float]:
        """Tasks planned so far and those RRT* did not solve in its time (evaluation tasks included)."""
        trees = self.planner
        return {
            keys.CURRICULUM_RRT_TASKS: trees.solved + trees.unsolved,
            keys.CURRICULUM_RRT_UNSOLVED: trees.unsolved,
        }

    @property
    def collision_checks(self) -> int:
        return self.planner.checks

    def learned_parts(self) -> dict[str, list]:
        return {}

    def tree_extras(self) -> dict[str, np.ndarray]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        """The trees planned so far and RRT*'s counts: a resumed run plans no task twice."""
        return self.planner.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.planner.load_state_dict(state)
