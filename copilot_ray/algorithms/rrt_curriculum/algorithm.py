"""The classical-planner curriculum: `RRTCurriculumConfig` and `RRTCurriculum`.

CO-PILOT's agent side as it is (GoalSAC: the traversal env, b repetitions of each task mini-batch, the
fast SAC learner, evaluation on validation and test tasks) on sub-goal trees cut from RRT* paths
(`copilot_ray.planning.rrt_trees`): layer k of a task's tree is its RRT* path cut into 2^k pieces of
equal length. There is no learned planner, cost model or alpha schedule, so set beside CO-PILOT it asks
whether CO-PILOT's lead comes from co-training its planner or from a planner that uses the map.

    config = RRTCurriculumConfig().environment("maze-point", env_config={"layout": "four-rooms"})
    algo = config.agent(tree_depth=5, repetitions=5).build_algo()

Evaluation follows each validation and test task's own RRT* tree (its finest path, tau_max steps per
sub-goal), planned at the first evaluation and kept; every RRT* check, for training and evaluation
trees alike, is counted as `copilot/privileges/collision_checks`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, ClassVar

from ray.rllib.utils.annotations import override

from copilot_ray import keys
from copilot_ray.algorithms.rrt_curriculum import settings as curriculum_settings
from copilot_ray.algorithms.sac.algorithm import GoalSAC, GoalSACConfig
from copilot_ray.planning.rrt_trees import RRTTrees
from copilot_ray.settings import Setting

_STATE_KEY = "rrt_curriculum"


class RRTCurriculumConfig(GoalSACConfig):
    """The goal-conditioned agent's config with CO-PILOT's tree settings (`tree_depth`, `repetitions`, the
    traversal readings; set with `.agent(...)`) and RRT*'s (`curriculum.rrt_time_s`)."""

    SETTINGS: ClassVar[Mapping[str, Setting]] = curriculum_settings.SETTINGS
    NESTED: ClassVar[tuple[str, ...]] = ("curriculum",)

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or RRTCurriculum)

    @override(GoalSACConfig)
    def validate(self) -> None:
        self._check_settings()
        # null tau_max: the test budget (tau_max x 2^K) stays TASK_STEPS whatever K.
        self.tau_max = curriculum_settings.tau_max_of(
            {"tau_max": self.tau_max, "tree_depth": self.tree_depth}
        )
        super().validate()


class RRTCurriculum(GoalSAC):
    """GoalSAC traversing trees cut from RRT* paths (module docstring)."""

    @classmethod
    @override(GoalSAC)
    def get_default_config(cls):
        return RRTCurriculumConfig()

    @override(GoalSAC)
    def setup(self, config) -> None:
        super().setup(config)
        cfg = self.config
        seed = 0 if cfg.seed is None else int(cfg.seed)
        self.rrt_trees = RRTTrees(self.goal_env, cfg.tree_depth, cfg.curriculum["rrt_time_s"], seed=seed)

    def _trees(self, idx, stats, timing):
        """Each drawn task's RRT* tree (planned the first time the task is drawn)."""
        t0 = time.perf_counter()
        trees = self.rrt_trees.sample(self.train_starts[idx], self.train_goals[idx])
        timing["planner_s"] += time.perf_counter() - t0
        return trees

    def _collision_checks(self) -> int:
        return self.rrt_trees.checks

    def _log_iteration(self, timing: Mapping[str, float]) -> None:
        self._log_rrt_counts()

    def _evaluate(self) -> None:
        super()._evaluate()
        self._log_rrt_counts()  # the evaluation tasks' trees, planned at the first evaluation

    def _log_rrt_counts(self) -> None:
        trees = self.rrt_trees
        self.metrics.log_value(
            keys.metric_path(keys.CURRICULUM_RRT_TASKS), trees.solved + trees.unsolved, window=1
        )
        self.metrics.log_value(keys.metric_path(keys.CURRICULUM_RRT_UNSOLVED), trees.unsolved, window=1)

    def _evaluation_plan(self, n: int) -> dict[str, Any]:
        """The agent follows each task's RRT* tree's finest path, `step_limit_of(K)` per sub-goal."""
        return {
            "planner": self.rrt_trees,
            "step_limit_of": lambda k: self.rules.step_limit_of(k, self.config.tree_depth),
            "planned_total_steps": None,
        }

    def _own_state(self) -> dict[str, Any]:
        """The trees planned so far and RRT*'s counts: a resumed run plans no task twice."""
        return {_STATE_KEY: self.rrt_trees.state_dict()}

    def _set_own_state(self, state: dict[str, Any]) -> None:
        if _STATE_KEY in state:
            self.rrt_trees.load_state_dict(state[_STATE_KEY])
