"""How the goal-conditioned agent traverses its trees on the env runners (the paper's Algorithm 2), with
SAC updates in between: `RunnerTraversal`, a part of `GoalSAC` (algorithm.py), which gives it the env
runner group, the learner, the agent updater and the metrics.

Tasks are split over the healthy runners; each runner's traversal env gets its share as a
`TraversalPlan` and runs one episode per sub-task; every round each runner runs its next
`subtasks_per_sample` sub-tasks, then the learner does `utd_ratio()` gradient steps per new env step and
the runners get the new weights. A runner that dies mid-repetition takes its sub-tasks with it: counted
(`copilot/agent/subtasks_lost`), logged, and the traversal goes on with the others.
"""

from __future__ import annotations

import logging
import time

import numpy as np
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    LEARNER_RESULTS,
    NUM_AGENT_STEPS_SAMPLED_LIFETIME,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
)

from copilot_ray import keys
from copilot_ray.algorithms.sac.traversal_channel import (
    Subtasks,
    TraversalPlan,
    concatenated,
    is_idle,
    load_plan,
    remaining,
    subtask_records,
)

logger = logging.getLogger(__name__)
RUNNER_RESTORE_TIMEOUT_S = 120  # waiting for a failed env runner to come back when none is left


class RunnerTraversal:
    """The traversal of trees on the env runners (module docstring); mixed into GoalSAC."""

    def _runner_ids(self) -> list[int]:
        """The runners to traverse on: the local one without remote runners, else the healthy remote
        ones, after trying to bring back failed ones (as RLlib does before each iteration: a runner that
        died in one repetition is back for the next)."""
        group = self.env_runner_group
        if group.num_remote_env_runners() == 0:
            return [0]
        if group.num_healthy_remote_env_runners() < group.num_remote_env_runners():
            self.restore_env_runners(group)
        # With none left, wait for Ray to restart one (its actors restart on their own, in seconds).
        deadline = time.monotonic() + RUNNER_RESTORE_TIMEOUT_S
        while not group.healthy_env_runner_ids() and time.monotonic() < deadline:
            time.sleep(1.0)
            self.restore_env_runners(group)
        healthy = sorted(group.healthy_env_runner_ids())
        if not healthy:
            raise RuntimeError(
                f"every env runner has failed and none came back within {RUNNER_RESTORE_TIMEOUT_S} s"
            )
        return healthy

    def _traverse(self, trees: np.ndarray, task_ids: np.ndarray) -> Subtasks:
        """Bottom-up traversal of every tree on the env runners, with SAC updates in between.

        Tasks are split over the runners; each round every runner runs its next
        `subtasks_per_sample` sub-tasks, then the learner does `config.utd_ratio()` gradient steps
        per new env step and the runners get the new weights.
        """
        cfg = self.config
        runner_ids = self._runner_ids()
        local = runner_ids == [0]
        shares = {rid: np.arange(i, len(trees), len(runner_ids)) for i, rid in enumerate(runner_ids)}
        plans = {rid: TraversalPlan(trees[s], cfg.tree_depth, task_ids[s]) for rid, s in shares.items()}
        depth = cfg.tree_depth

        # Every call returns its runner's index: a runner that dies mid-iteration is simply missing from
        # the results (RLlib's restart_failed_env_runners), and its sub-tasks are counted as lost.
        def load(runner):
            return runner.worker_index, load_plan(runner, plans[runner.worker_index])

        loaded = dict(
            self.env_runner_group.foreach_env_runner(
                load, local_env_runner=local, remote_worker_ids=None if local else runner_ids
            )
        )
        per_tree = 2 ** (depth + 1) - 1  # sub-tasks of one tree, all layers
        queued = {}
        for rid in runner_ids:
            if rid in loaded:
                queued[rid] = loaded[rid]
            else:
                self._lose_subtasks(rid, len(shares[rid]) * per_tree)
        chunk = cfg.subtasks_per_sample
        records: list[Subtasks] = []
        while any(queued.values()):

            def sample(runner):
                left = remaining(runner)
                if left == 0:
                    return runner.worker_index, [], runner.get_metrics(), 0
                episodes = runner.sample(num_episodes=min(chunk, left), explore=True)
                return runner.worker_index, episodes, runner.get_metrics(), remaining(runner)

            active = [rid for rid, n in queued.items() if n > 0]
            results = self.env_runner_group.foreach_env_runner(
                sample, local_env_runner=local, remote_worker_ids=None if local else active
            )
            episodes = []
            runner_metrics = []
            answered = set()
            for rid, eps, metrics, left in results:
                answered.add(rid)
                queued[rid] = left
                episodes.extend(eps)
                runner_metrics.append(metrics)
            for rid in set(active) - answered:  # died during this round
                self._lose_subtasks(rid, queued.pop(rid))
            episodes = self._took(episodes, runner_metrics, records)
            if episodes:
                self._learn(episodes)
            self.heartbeat.beat(self._traversal_progress)
        if not records:
            raise RuntimeError("no sub-task of this repetition was traversed: every env runner failed")
        return concatenated(records)

    def _traversal_progress(self) -> str:
        """The heartbeat's line during a traversal (cheap: built at every beat)."""
        return (
            f"iteration {self.iteration + 1}: repetition {self._batch_done + 1} of {self.config.repetitions}, "
            f"{self._env_steps():,} env steps, {self._updates_done:,} SAC updates this iteration"
        )

    def _lose_subtasks(self, runner_id: int, count: int) -> None:
        """A runner died with `count` sub-tasks of this repetition: counted, logged, not hidden."""
        self._subtasks_lost += int(count)
        logger.warning(
            "env runner %d failed during the traversal: its %d remaining sub-tasks of this repetition are "
            "lost (%s; RLlib restores the runner before the next iteration)",
            runner_id,
            count,
            keys.AGENT_SUBTASKS_LOST,
        )

    def _took(self, episodes, runner_metrics, records: list[Subtasks]) -> list:
        """A round's sampled episodes: the runners' metrics aggregated, the placeholder episodes of an
        idle env dropped, the sub-tasks' records kept in `records`; the episodes left."""
        self.metrics.aggregate(runner_metrics, key=ENV_RUNNER_RESULTS)
        episodes = [e for e in episodes if not is_idle(e.get_infos(-1))]
        if episodes:
            records.append(subtask_records(episodes))
        return episodes

    def _learn(self, episodes) -> None:
        owed = self._owed_updates(episodes)
        if owed is None:
            return
        t0 = time.perf_counter()
        learner_results = self.agent_updater.update(*owed)
        self._updated(owed[0], learner_results, time.perf_counter() - t0)

    def _owed_updates(self, episodes) -> tuple[int, dict[str, int]] | None:
        """Adds `episodes` to the replay; the gradient steps they make due and the timesteps the learner
        logs with them (None: no step due)."""
        new_steps = sum(len(e) for e in episodes)
        self.agent_updater.add(episodes)
        num_updates = self.gradient_steps.on_env_steps(new_steps)
        if num_updates == 0:
            return None
        lifetime = self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)
        return num_updates, {
            NUM_ENV_STEPS_SAMPLED_LIFETIME: lifetime,
            NUM_AGENT_STEPS_SAMPLED_LIFETIME: lifetime,
        }

    def _updated(self, num_updates: int, learner_results, seconds: float, sync: bool = True) -> None:
        """After `num_updates` gradient steps (taking `seconds`): counted, their results logged, and
        (`sync`) the runners given the new weights."""
        self._update_seconds += seconds
        self._updates_done += num_updates
        if learner_results:
            self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        if sync:
            self._sync_runners()

    def _sync_runners(self) -> None:
        """The env runners' modules given the learner's weights."""
        self.env_runner_group.sync_weights(
            from_worker_or_learner_group=self.learner_group, inference_only=True
        )
