"""NEXTTrial: NEXT trained and scored as a sweep trial (see copilot_ray.trials.planning_trial)."""

from __future__ import annotations

from typing import Any

import numpy as np

from copilot_ray.planning.next_planner import NEXTPlanner, padded_paths, rrt_star_demonstrations
from copilot_ray.planning.path_metrics import path_metrics, rrt_reference, score_paths
from copilot_ray.trials.planning_trial import PlanningTrial


class NEXTTrial(PlanningTrial):
    """Iteration 0 imitates the demonstrations, each later one is a self-improvement round; every
    iteration then searches the scored test tasks with the model.

    The collision checks reported are those of training so far (the demonstrations' too) plus this
    iteration's evaluation: what the paths scored cost. Earlier evaluations are measurements that train
    nothing, so they are not carried over. The evaluation's noise is seeded by (seed, round), so it does
    not disturb the training stream and a restored trial evaluates identically."""

    def start(self, cfg, env) -> None:
        self.planner = NEXTPlanner.for_env(env, cfg.search_settings(), cfg.train_settings(), cfg.seed)
        maze = env.unwrapped
        self.train_starts, self.train_goals = (x.astype(np.float64) for x in maze.tasks("train"))
        starts, goals = (x.astype(np.float64) for x in maze.tasks("test"))
        self.test_starts, self.test_goals = starts[: cfg.eval_num_tasks], goals[: cfg.eval_num_tasks]
        self.round = 0
        self.reference = None
        if cfg.rrt_reference_time_s > 0:
            self.reference = rrt_reference(
                cfg.env_id, cfg.env_config, len(self.test_starts), cfg.rrt_reference_time_s, cfg.seed
            )

    def _demonstrate(self) -> None:
        cfg, planner = self.cfg, self.planner
        n = min(cfg.num_demos, len(self.train_starts))
        starts, goals = self.train_starts[:n], self.train_goals[:n]
        if cfg.demonstrator == "rrt_star":
            paths, checks = rrt_star_demonstrations(self.env, starts, goals, cfg.demo_time_s, cfg.seed)
            planner.add_checks(checks)
        else:
            results = [
                planner.search(s, g, guided=False, improve_iterations=cfg.train_improve_iterations)
                for s, g in zip(starts, goals, strict=True)
            ]
            paths = [r.path if r.solved else None for r in results]
        planner.imitate(paths, goals)
        planner.train(cfg.demo_train_steps)

    def iterate(self) -> tuple[dict[str, float], int, bool]:
        cfg, planner = self.cfg, self.planner
        if self.round == 0:
            self._demonstrate()
        else:
            size = min(cfg.tasks_per_round, len(self.train_starts))
            idx = planner.rng.choice(len(self.train_starts), size=size, replace=False)
            planner.self_improve(
                self.train_starts[idx],
                self.train_goals[idx],
                cfg.round_train_steps,
                cfg.train_improve_iterations,
            )
        self.round += 1
        training_checks = planner.checks
        rng = np.random.default_rng([cfg.seed, self.round, 7])  # evaluation noise, apart from training's
        results = [
            planner.search(s, g, rng=rng) for s, g in zip(self.test_starts, self.test_goals, strict=True)
        ]
        planner.checks = training_checks  # evaluations train nothing: not carried to the next iteration
        checks = training_checks + sum(r.checks for r in results)
        scores = score_paths(self.env.unwrapped, padded_paths(results), self.test_goals)
        metrics = path_metrics(scores, checks, self.reference)
        return metrics, checks, self.round > cfg.self_improve_rounds

    def state(self) -> dict[str, Any]:
        return {"planner": self.planner.state_dict(), "round": self.round}

    def restore_state(self, state: dict) -> None:
        self.planner.load_state_dict(state["planner"])
        self.round = int(state["round"])
