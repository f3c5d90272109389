"""RRTStarTrial: RRT* on the test tasks as a sweep trial (see copilot_ray.trials.planning_trial)."""

from __future__ import annotations

from typing import Any

import numpy as np

from copilot_ray.planning.path_metrics import (
    PathScores,
    RRTReference,
    path_metrics,
    reference_path,
)
from copilot_ray.planning.rrt_star import rrt_star_for_env
from copilot_ray.trials.planning_trial import PlanningTrial


class RRTStarTrial(PlanningTrial):
    """Plans ``tasks_per_iteration`` test tasks per iteration; the metrics cover the tasks planned so far
    (normalised by themselves: RRT* is the reference). Done after ``eval_num_tasks``; the whole run is then
    stored as the RRT* reference for these settings (unless one is stored already)."""

    def start(self, cfg, env) -> None:
        maze = env.unwrapped
        starts, goals = (x.astype(np.float64) for x in maze.tasks("test"))
        self.num_tasks = min(cfg.eval_num_tasks, len(starts))
        self.starts, self.goals = starts[: self.num_tasks], goals[: self.num_tasks]
        self.rrt = rrt_star_for_env(env, time_limit_s=cfg.time_limit_s, seed=cfg.seed)
        if cfg.range is not None:
            self.rrt.range = cfg.range
        self.solved: list[bool] = []
        self.length: list[float] = []
        self.checks: list[int] = []

    def iterate(self) -> tuple[dict[str, float], int, bool]:
        maze = self.env.unwrapped
        first = len(self.solved)
        for i in range(first, min(first + self.cfg.tasks_per_iteration, self.num_tasks)):
            r = self.rrt.plan(self.starts[i], self.goals[i], maze.success_radius)
            self.solved.append(r.solved)
            self.length.append(r.length)
            self.checks.append(r.collision_checks)
        reference = RRTReference(
            np.array(self.solved, bool), np.array(self.length, np.float64), np.array(self.checks, np.int64)
        )
        total = int(reference.checks.sum())
        metrics = path_metrics(PathScores(reference.solved, reference.length), total, reference)
        done = len(self.solved) >= self.num_tasks
        if done:
            self._store_reference(reference)
        return metrics, total, done

    def _store_reference(self, reference: RRTReference) -> None:
        cfg = self.cfg
        if cfg.range is not None:  # the shared reference is RRT* at OMPL's default range
            return
        path = reference_path(cfg.env_id, cfg.env_config, self.num_tasks, cfg.time_limit_s, cfg.seed)
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            reference.save(path)

    def state(self) -> dict[str, Any]:
        return {"solved": self.solved, "length": self.length, "checks": self.checks}

    def restore_state(self, state: dict) -> None:
        self.solved, self.length, self.checks = (list(state[k]) for k in ("solved", "length", "checks"))
