"""SGTPGTrial: SGT-PG trained and scored as a sweep trial (see copilot_ray.trials.planning_trial)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from copilot_ray import keys
from copilot_ray.planning import SegmentCost, SubgoalPlanner
from copilot_ray.planning.path_metrics import CountedChecks, path_metrics, rrt_reference, score_paths
from copilot_ray.planning.planner_phases import PlannerPhases
from copilot_ray.trials.planning_trial import PlanningTrial


class SGTPGTrial(PlanningTrial):
    """``phases_per_iteration`` planner phases on random training tasks, then the mean tree of every
    scored test task: its finest path's success, length and the checks spent in training so far."""

    def start(self, cfg, env) -> None:
        torch.manual_seed(cfg.seed)
        maze = env.unwrapped
        self.planner = SubgoalPlanner.from_settings(
            cfg.planner,
            maze.goal_dim,
            cfg.tree_depth,
            maze.goal_space.low,
            maze.goal_space.high,
            cfg.seed,
            geometry=maze.agent_geometry,
        )
        # CO-PILOT's planner phase (std annealing included), on the Euclidean + collision cost alone.
        self.phases = PlannerPhases(self.planner, cfg.planner)
        self.checks = CountedChecks(maze.segments_collide)
        self.cost = SegmentCost(
            alpha=1.0,
            segments_collide=self.checks,
            distance=maze.goal_distance,
            collision_penalty=cfg.collision_penalty,
        )
        self.train_starts, self.train_goals = maze.tasks("train")
        starts, goals = maze.tasks("test")
        self.test_starts, self.test_goals = starts[: cfg.eval_num_tasks], goals[: cfg.eval_num_tasks]
        self.rng = np.random.default_rng(cfg.seed)
        self.reference = None
        if cfg.rrt_reference_time_s > 0:
            self.reference = rrt_reference(
                cfg.env_id, cfg.env_config, len(self.test_starts), cfg.rrt_reference_time_s, cfg.seed
            )

    def iterate(self) -> tuple[dict[str, float], int, bool]:
        cfg = self.cfg
        for _ in range(cfg.phases_per_iteration):
            batch = min(cfg.task_batch_size, len(self.train_starts))
            idx = self.rng.choice(len(self.train_starts), size=batch, replace=False)
            self.phases.run(
                self.train_starts[idx], self.train_goals[idx], cfg.tree_depth, self.cost, self.rng
            )
        trees = self.planner.sample(self.test_starts, self.test_goals, deterministic=True)
        scores = score_paths(self.env.unwrapped, trees, self.test_goals)
        metrics = path_metrics(scores, self.checks.count, self.reference)
        metrics[keys.PLANNER_UPDATES] = float(self.phases.count)
        return metrics, self.checks.count, False

    def state(self) -> dict[str, Any]:
        return {
            "planner": self.planner.state_dict(),
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "phases": self.phases.count,
            "checks": self.checks.count,
        }

    def restore_state(self, state: dict) -> None:
        self.planner.load_state_dict(state["planner"])
        self.rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"])
        self.phases.count, self.checks.count = int(state["phases"]), int(state["checks"])
