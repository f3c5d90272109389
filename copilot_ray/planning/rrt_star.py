"""RRT* from OMPL (the `ompl` wheel) on a goal-conditioned env's own validity and motion checks.

The baseline planner of the paper's Fig. 4b/4c. The configuration space is OMPL's compound of
real-vector parts and an SO(2) for every wrapped angle, so OMPL interpolates angles the short way round,
as the envs' motion checks do. A state is valid when `is_free(config)`; a motion when
`motion_free(a, b)` (for the maze: exact for the point mass, conservative advancement for the rigid body
and the snake). Both callbacks are counted: that count is the "collision checks" of Fig. 4c.

OMPL's path-length objective measures a compound state space as the weighted sum of its parts'
distances (an L1 over parts); `weights` weight each dimension like the env's distance does (the
geometry's `distance_weights`). The goal
is reached within `goal_radius` in that metric, which is never less than the env's Euclidean-style
distance, so a solved path ends within the env's success radius too. Path lengths returned are in the
env's own distance (`distance` callback), for comparison with other planners.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

try:  # OMPL is a dependency, but only the RRT* baseline needs it: import errors surface when planning
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou
except ImportError as err:  # pragma: no cover - exercised only without the wheel
    _IMPORT_ERROR: ImportError | None = err
else:
    _IMPORT_ERROR = None


@dataclass
class RRTStarResult:
    """One planning query."""

    solved: bool  # an exact solution: a collision-free path to within goal_radius of the goal
    path: np.ndarray  # [P, d] configurations, start first (empty when not solved)
    length: float  # in the env's distance; inf when not solved
    state_checks: int  # validity callback calls
    motion_checks: int  # motion callback calls
    seconds: float

    @property
    def collision_checks(self) -> int:
        return self.state_checks + self.motion_checks


def _groups(weights: Sequence[float], angle_dims: Sequence[int]) -> list[tuple[str, list[int], float]]:
    """Config dims as OMPL subspaces, in order: ("angle", [i], w) for each wrapped angle, and runs of
    consecutive other dims of equal weight as ("vector", [i, ...], w)."""
    out: list[tuple[str, list[int], float]] = []
    for i, w in enumerate(weights):
        kind = "angle" if i in angle_dims else "vector"
        if out and kind == "vector" and out[-1][0] == "vector" and out[-1][2] == w:
            out[-1][1].append(i)
        else:
            out.append((kind, [i], float(w)))
    return out


class RRTStar:
    """RRT* over one configuration space; `plan(start, goal)` answers one query."""

    def __init__(
        self,
        low: np.ndarray,
        high: np.ndarray,
        is_free: Callable[[np.ndarray], bool],
        motion_free: Callable[[np.ndarray, np.ndarray], bool],
        distance: Callable[[np.ndarray, np.ndarray], float],
        *,
        angle_dims: Sequence[int] = (),
        weights: Sequence[float] | None = None,
        time_limit_s: float = 1.0,
        range_: float | None = None,
        seed: int = 0,
    ):
        if _IMPORT_ERROR is not None:
            raise ImportError(f"RRT* needs OMPL's Python wheel (`pip install ompl`): {_IMPORT_ERROR}")
        if not time_limit_s > 0:
            raise ValueError(f"time_limit_s must be > 0, got {time_limit_s!r}")
        self.low, self.high = np.asarray(low, np.float64), np.asarray(high, np.float64)
        self.dim = len(self.low)
        weights = [1.0] * self.dim if weights is None else [float(w) for w in weights]
        if len(weights) != self.dim:
            raise ValueError(f"weights must have one entry per dimension ({self.dim}), got {weights}")
        self.groups = _groups(weights, list(angle_dims))
        self.is_free, self.motion_free, self.distance = is_free, motion_free, distance
        self.time_limit_s = float(time_limit_s)
        self.range = range_
        ou.setLogLevel(ou.LOG_WARN)
        _seed_once(seed)
        self.space = ob.CompoundStateSpace()
        for kind, dims, weight in self.groups:
            if kind == "angle":
                self.space.addSubspace(ob.SO2StateSpace(), weight)
            else:
                sub = ob.RealVectorStateSpace(len(dims))
                bounds = ob.RealVectorBounds(len(dims))
                for j, i in enumerate(dims):
                    bounds.setLow(j, float(self.low[i]))
                    bounds.setHigh(j, float(self.high[i]))
                sub.setBounds(bounds)
                self.space.addSubspace(sub, weight)

    # ------------------------------------------------------------------------------------ states
    def _to_config(self, state) -> np.ndarray:
        c = np.empty(self.dim)
        for k, (kind, dims, _) in enumerate(self.groups):
            if kind == "angle":
                c[dims[0]] = state[k].value
            else:
                for j, i in enumerate(dims):
                    c[i] = state[k][j]
        return c

    def _to_state(self, config: np.ndarray):
        state = self.space.allocState()
        for k, (kind, dims, _) in enumerate(self.groups):
            if kind == "angle":
                state[k].value = float(config[dims[0]])
            else:
                for j, i in enumerate(dims):
                    state[k][j] = float(config[i])
        return state

    # ------------------------------------------------------------------------------------ query
    def plan(self, start: np.ndarray, goal: np.ndarray, goal_radius: float) -> RRTStarResult:
        """Plan from `start` to within `goal_radius` of `goal` for `time_limit_s` seconds (RRT* keeps
        improving its path until then). A start in collision is refused (OMPL would only log it); a goal
        in an obstacle is allowed (its radius may still hold free configurations) and simply not solved."""
        start = np.asarray(start, np.float64)
        if start.shape != (self.dim,) or not bool(self.is_free(start)):
            raise ValueError(
                f"start {np.round(start, 4).tolist()} lies in an obstacle or outside the configuration space "
                f"(a {self.dim}-d configuration within {self.low.tolist()} .. {self.high.tolist()})"
            )
        counts = {"state": 0, "motion": 0}
        si = ob.SpaceInformation(self.space)

        def valid(state) -> bool:
            counts["state"] += 1
            return bool(self.is_free(self._to_config(state)))

        outer = self

        class MotionValidator(ob.MotionValidator):
            def checkMotion(self, s1, s2, *args) -> bool:  # noqa: N802 - OMPL's name
                counts["motion"] += 1
                return bool(outer.motion_free(outer._to_config(s1), outer._to_config(s2)))

        si.setStateValidityChecker(valid)
        validator = MotionValidator(si)
        si.setMotionValidator(validator)
        si.setup()
        problem = ob.ProblemDefinition(si)
        problem.setStartAndGoalStates(self._to_state(start), self._to_state(goal), float(goal_radius))
        problem.setOptimizationObjective(ob.PathLengthOptimizationObjective(si))
        planner = og.RRTstar(si)
        if self.range is not None:
            planner.setRange(float(self.range))
        planner.setProblemDefinition(problem)
        planner.setup()
        t0 = time.perf_counter()
        planner.solve(self.time_limit_s)
        seconds = time.perf_counter() - t0
        solved = bool(problem.hasExactSolution())
        if solved:
            raw = problem.getSolutionPath()
            path = np.array([self._to_config(raw.getState(i)) for i in range(raw.getStateCount())])
            length = float(sum(self.distance(p, q) for p, q in zip(path[:-1], path[1:], strict=True)))
        else:
            path, length = np.zeros((0, self.dim)), float("inf")
        return RRTStarResult(solved, path, length, counts["state"], counts["motion"], seconds)


_SEEDED: list[int] = []


def _seed_once(seed: int) -> None:
    """OMPL's random generator takes a seed once per process, before its first use; later planners
    share that stream (so a run of queries is reproducible, one query on its own is not)."""
    if not _SEEDED:
        ou.RNG.setSeed(int(seed) + 1)  # OMPL refuses 0
        _SEEDED.append(int(seed))


def rrt_star_for_env(env, time_limit_s: float = 3.0, seed: int = 0) -> RRTStar:
    """RRT* on a maze env's configuration space, validity (`is_free`) and motion checks
    (`segments_collide`); angles and their weights from the env's agent geometry."""
    maze = env.unwrapped
    geometry = maze.agent_geometry
    low, high = geometry.bounds
    return RRTStar(
        low,
        high,
        is_free=maze.is_free,
        motion_free=lambda a, b: not bool(maze.segments_collide(a[None], b[None])[0]),
        distance=lambda a, b: float(maze.goal_distance(a, b)),
        angle_dims=geometry.angle_dims,
        weights=geometry.distance_weights,
        time_limit_s=time_limit_s,
        seed=seed,
    )
