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

from collections.abc import Mapping
from typing import ClassVar

from ray.rllib.utils.annotations import override

from copilot_ray.algorithms.rrt_curriculum import settings as curriculum_settings
from copilot_ray.algorithms.sac.algorithm import GoalSAC, GoalSACConfig
from copilot_ray.planning.rrt_trees import RRTTreeCurriculum
from copilot_ray.settings import Setting


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

    def make_curriculum(
        self, env, train_tasks, probe_starts, reachable_length, rng, seed
    ) -> RRTTreeCurriculum:
        return RRTTreeCurriculum(
            env, self.tree_depth, self.repetitions, self.curriculum["rrt_time_s"], seed=seed
        )


class RRTCurriculum(GoalSAC):
    """GoalSAC with the RRT* curriculum (module docstring): its state under "rrt_curriculum"."""

    @classmethod
    @override(GoalSAC)
    def get_default_config(cls):
        return RRTCurriculumConfig()
