"""How the goal-conditioned agent is evaluated: `PlannedEvaluation`, a part of `GoalSAC` (algorithm.py).

Every evaluation runs the validation tasks (headline figures: what searchers read), then the test tasks
(everything the report shows), with the same plan: the agent following its curriculum's planner's finest
path (`_evaluation_plan`; SoRB: its graph's waypoints), or alone without one. The figures themselves are
the protocol every agent-based method shares (`copilot_ray.evaluation.AgentEvaluation`); what is the
plan's own is here: its collision-free share, its paths scored as a motion planner's (`paths/*`), the
sub-goal trees of a few test tasks saved per evaluation (`copilot_trees/*.npz`), and on an env with its
own episode-level measure (the walker) that measure.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray import keys
from copilot_ray.evaluation import EVAL_SPLITS, ModulePolicy, evaluate_copilot
from copilot_ray.planning.path_metrics import path_metrics, rrt_reference


def obstacle_arrays(env) -> dict[str, np.ndarray]:
    """The env's obstacle boxes and region for the tree artifact (empty for an env without `obstacles`)."""
    obstacles = getattr(env, "obstacles", None)
    if obstacles is None:
        return {}
    return {
        "walls_lo": obstacles.lo,
        "walls_hi": obstacles.hi,
        "region": np.stack([obstacles.region_lo, obstacles.region_hi]),
    }


class PlannedEvaluation:
    """The agent's evaluation (module docstring); mixed into GoalSAC."""

    def _evaluation_plan(self, n: int) -> dict[str, Any] | None:
        """How the planned evaluation runs: the planner (anything with `sample(starts, goals,
        deterministic=True)`: the curriculum's; None: the agent alone), the steps per waypoint of layer
        k, optionally `hop_limits(waypoints)` (per-task, per-hop steps, [N, P - 1]) and a total cap. None:
        nothing to evaluate yet."""
        return {
            "planner": None if self.curriculum is None else self.curriculum.planner,
            "step_limit_of": lambda k: self.rules.step_limit_of(k, self.config.tree_depth),
            "planned_total_steps": None,
        }

    def _evaluate_mastery(self, policy, planner, split: str) -> None:
        """On an env with its own episode-level measure (the walker's mastered track distributions,
        `mastery`): the agent following the plan of the first test task (all share one task there), or
        alone without a planner, on the tracks of `split`."""
        mastery = getattr(self.goal_env.unwrapped, "mastery", None)
        if mastery is None:
            return
        path = None
        if planner is not None:
            path = planner.sample(self.test_starts[:1], self.test_goals[:1], deterministic=True)[0]
        result = mastery(policy, path, with_delta=self.rules.agent_input == "state_goal_delta", split=split)
        self._log_eval(split, {keys.EVAL_MASTERED: result.mastered_fraction})
        self._log_eval(split, {keys.EVAL_ENV_RETURN: float(result.returns.mean())})

    def _task_reward(self) -> float:
        """R: what reaching a whole task's goal is worth (the goal env's reward x reward_scale)."""
        return float(getattr(self.goal_env.unwrapped, "goal_reward", 1.0)) * self.rules.reward_scale

    def _log_eval(self, split: str, figures: Mapping[str, float]) -> None:
        """Evaluation figures of `split` (copilot/eval/...): as they are for test, their validation twins else."""
        self._log(figures if split == "test" else {keys.validation_key(k): v for k, v in figures.items()})

    def _evaluate(self) -> None:
        """The validation tasks (headline figures only: what searchers read), then the test tasks
        (everything the report shows), with the same plan and policy."""
        plan = self._evaluation_plan(self.evaluation.num_tasks)
        if plan is None:
            return
        env_steps = self._env_steps()
        n = self.evaluation.num_tasks
        self.heartbeat.say(f"evaluating on {n} validation and {n} test tasks at {env_steps:,} env steps")
        for split in EVAL_SPLITS:
            self._evaluate_split(split, plan, env_steps)

    def _evaluate_split(self, split: str, plan: dict[str, Any], env_steps: int) -> None:
        cfg = self.config
        test = split == "test"
        starts, goals = self.evaluation.tasks[split]
        module = self.get_module(DEFAULT_MODULE_ID)
        # The headline action goes first: it also drives the sub-goal tree figure's rollouts.
        policies = {
            action: ModulePolicy(module) if seed is None else ModulePolicy(module, sampled=True, seed=seed)
            for action, seed in self.evaluation.action_seeds(split, cfg.seed, self.iteration).items()
        }
        result = evaluate_copilot(
            goal_env_id=cfg.goal_env,
            goal_env_config=cfg.goal_env_config,
            policies=policies,
            starts=starts,
            goals=goals,
            depth=cfg.tree_depth,
            tau_max=cfg.tau_max,
            tree_tasks=self._tree_tasks(len(starts)) if test else 0,
            with_delta=self.rules.agent_input == "state_goal_delta",
            **plan,
        )
        self._log(self.evaluation.figures(split, result.by_action, env_steps))
        self._evaluate_mastery(policies[cfg.eval_action], plan["planner"], split)
        self._log_eval(split, {keys.PLANNED_COLLISION_FREE: result.plan_collision_free})
        if not test:
            return
        if plan["planner"] is not None:  # without a plan, [s0, g] is not a path worth scoring
            self._log(
                path_metrics(result.plan_scores, self._collision_checks(), self._rrt_reference(len(starts)))
            )
        if result.trees is not None:
            self._save_tree_artifact(result, env_steps)

    def _tree_tasks(self, n: int) -> int:
        """Test tasks whose sub-goal trees are traversed layer by layer for the tree figure (CO-PILOT's
        `eval_tree_tasks`; none without a curriculum)."""
        return 0 if self.curriculum is None else min(getattr(self.config, "eval_tree_tasks", 0), n)

    def _rrt_reference(self, n: int):
        """The RRT* reference the paths' ratios divide by (CO-PILOT's `eval_rrt_reference_s` > 0),
        computed at the first evaluation that needs it; None without one."""
        cfg = self.config
        if getattr(cfg, "eval_rrt_reference_s", 0) > 0 and self._rrt_cache is None:
            seed = 0 if cfg.seed is None else int(cfg.seed)
            self._rrt_cache = rrt_reference(
                cfg.goal_env, cfg.goal_env_config, n, cfg.eval_rrt_reference_s, seed
            )
        return self._rrt_cache

    def _save_tree_artifact(self, result, env_steps: int) -> None:
        """Sub-goal trees of fixed test tasks (all layers), the agent's steps per sub-task, the walls the
        planner sees and the curriculum's own extras (CO-PILOT: tau_hat's profile)."""
        env = self.goal_env.unwrapped
        directory = Path(self.logdir) / keys.TREES_DIR
        directory.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            directory / f"trees_iter{self.iteration + 1:06d}.npz",
            iteration=self.iteration + 1,
            env_steps=env_steps,
            depth=self.config.tree_depth,
            trees=result.trees,
            subtask_steps=result.tree_subtask_steps,
            subtask_reached=result.tree_subtask_reached,
            layout=np.array(str(self.config.goal_env_config.get("layout", ""))),
            # The obstacles the planner sees, so the figure draws any env's trees over its walls.
            **obstacle_arrays(env),
            **self.curriculum.tree_extras(),
        )
