"""Several seeds of one goal-conditioned SAC configuration trained in one loop (a spec's
`seeds_per_trial`): `SeedStack(algos)`, one `GoalSAC` per seed, all in this process.

Each seed keeps its own algorithm (its planner, curriculum, replay, evaluation, metrics and checkpoint,
exactly as a one-seed run's); what the stack shares is the loop. `run_iteration` advances every seed's
`iteration_steps` generator to its next traversal, then traverses all of them together: one loop over
the seeds' sub-tasks (`traversal_runner.run_together`: at every env step one act for every seed whose
sub-task is under way: one batched forward pass of the seeds' stacked actors, `SACStep.act`; on the
maze one `batch_step` moving all their agents), then the SAC updates every seed owes after its round of
`subtasks_per_sample` sub-tasks as one stacked step (`stacked_updates.StackedAgentUpdates`, the `active`
mask for the seeds that owe none), then every seed's next round. No thread and no global random
state: every seed draws from its own generators only (its env runner's action noise, its Philox update
and replay streams, its numpy rng for tasks and planner), so seed i of a stack trains as seed i alone,
whatever the other seeds draw (`tests/test_seed_stack_trial.py`). Each seed's `train()` afterwards
finds its iteration done and only does RLlib's bookkeeping (its result, its counters).

One stack, one path on every device: the stacked step at N seeds is the fused step of a one-seed
run at N = 1 (`gc_sac.sac_step`), captured as one CUDA graph on a GPU.

A seed whose iteration raises (a non-finite planner, a crashed env) stops alone: `run_iteration` returns
its error and the others go on (a stacked update that raises fails every seed in it).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from copilot_ray.algorithms.sac.stacked_updates import StackedAgentUpdates, stacking_problems
from copilot_ray.algorithms.sac.traversal_channel import (
    Subtasks,
    TraversalPlan,
    concatenated,
    load_plan,
    remaining,
)
from copilot_ray.algorithms.sac.traversal_runner import TraversalEnvRunner, run_together


def stack_problems(algos: Sequence[Any]) -> list[str]:
    """Why these algorithms cannot share one loop ([] when they can): each seed must sample in this
    process with the lean loop (its own noise); what the stacked update needs is its own check
    (`stacked_updates.stacking_problems`)."""
    first = algos[0].config
    problems = []
    if first.num_env_runners:
        problems.append(
            f"num_env_runners={first.num_env_runners}: a stack steps every seed in its process (0)"
        )
    runner = algos[0].env_runner_group.local_env_runner
    if not (isinstance(runner, TraversalEnvRunner) and runner.samples_lean(1)):
        problems.append(
            "lean_traversal=False or episode callbacks: a stack steps the seeds with the lean loop"
        )
    return problems + stacking_problems(algos)


class SeedStack:
    """N seeds' algorithms trained in one loop (module docstring)."""

    def __init__(self, algos: Sequence[Any]):
        problems = stack_problems(algos)
        if problems:
            raise ValueError("these seeds cannot be trained as one stack: " + "; ".join(problems))
        self.algos = list(algos)
        self.runners = [algo.env_runner_group.local_env_runner for algo in self.algos]
        # Each seed's traversal env; where its goal env moves many agents as arrays (the maze), every
        # env step moves all seeds' agents in one `batch_step`.
        self.envs = [runner.env.unwrapped.envs[0].unwrapped for runner in self.runners]
        batched = all(hasattr(e.inner, "batch_step") and hasattr(e.inner, "step_to") for e in self.envs)
        self._move = self._batch_move if batched else None
        self._for_env = self.runners[0]._action_for_env_fn()
        self.updates = StackedAgentUpdates(self.algos)
        for i, algo in enumerate(self.algos):
            algo.agent_updater = self.updates.view(i)  # its replay: its rings of the stacked buffer

    # ------------------------------------------------------------------ one iteration of every seed
    def run_iteration(self, indices: Sequence[int]) -> dict[int, Exception]:
        """One iteration of each seed in `indices`, their traversals together; {seed index: the error
        it stopped with} for those that failed. Each seed that did not is left to its `train()`."""
        steps = {i: self.algos[i].iteration_steps() for i in indices}
        errors: dict[int, Exception] = {}
        requests: dict[int, tuple] = {}

        def advance(i: int, subtasks: Subtasks | None) -> None:
            try:
                requests[i] = next(steps[i]) if subtasks is None else steps[i].send(subtasks)
            except StopIteration:
                pass
            except Exception as err:  # noqa: BLE001 - a seed's failure is its own
                errors[i] = err

        for i in indices:
            advance(i, None)
        while requests:
            pending, requests = requests, {}
            for i, result in self._traverse(pending).items():
                if isinstance(result, Exception):
                    errors[i] = result
                    steps[i].close()
                else:
                    advance(i, result)
        for i in indices:
            if i not in errors:
                self.algos[i].iteration_done = True
        return errors

    def _traverse(self, requests: Mapping[int, tuple[np.ndarray, np.ndarray]]) -> dict[int, Any]:
        """Every requesting seed's traversal of its trees, in rounds (`RunnerTraversal._traverse` for
        one local runner, the seeds' env steps in one loop): {seed index: its Subtasks, or its error}."""
        out: dict[int, Any] = {}
        left, records = {}, {i: [] for i in requests}
        for i, (trees, task_ids) in requests.items():
            algo = self.algos[i]
            left[i] = load_plan(self.runners[i], TraversalPlan(trees, algo.config.tree_depth, task_ids))
        while any(n > 0 for i, n in left.items() if i not in out):
            active = [i for i, n in left.items() if n > 0 and i not in out]
            chunk = {i: min(self.algos[i].config.subtasks_per_sample, left[i]) for i in active}
            sampled = run_together(
                {i: self.runners[i].subtask_steps(chunk[i], explore=True) for i in active},
                self._act,
                self._move,
            )
            owed = {}
            for i in active:
                algo, result = self.algos[i], sampled[i]
                if isinstance(result, Exception):
                    out[i] = result
                    continue
                left[i] = remaining(self.runners[i])
                episodes = algo._took(result, [self.runners[i].get_metrics()], records[i])
                due = algo._owed_updates(episodes) if episodes else None
                if due is not None:
                    owed[i] = due
            for i, results in self._update(owed).items():
                if isinstance(results, Exception):
                    out[i] = results
                else:
                    # its runner's module does not act here (the stacked actors do): synced once below
                    self.algos[i]._updated(owed[i][0], results[0], results[1], sync=False)
            for i in active:
                self.algos[i].heartbeat.beat(self.algos[i]._traversal_progress)
        for i in requests:
            if i not in out:
                self.algos[i]._sync_runners()  # what the seed's evaluation and checkpoint read
                if not records[i]:
                    out[i] = RuntimeError("no sub-task of this repetition was traversed")
                else:
                    out[i] = concatenated(records[i])
        return out

    def _act(self, ids: Sequence[int], observations: Sequence[np.ndarray]) -> list[np.ndarray]:
        """The exploring actions of seeds `ids` for their observations: each seed's noise from its own
        runner; one batched forward pass of the stacked actors."""
        step, device, n = self.updates.step, self.updates.device, len(self.algos)
        obs = torch.from_numpy(np.stack(observations).astype(np.float32, copy=False)).unsqueeze(1)
        noise = torch.cat([self.runners[i].draw_noise() for i in ids]).unsqueeze(1)
        if len(ids) < n:  # the seeds whose sub-task is under way, in their rows; the others' rows idle
            rows = torch.as_tensor(ids)
            obs = torch.zeros(n, *obs.shape[1:]).index_copy_(0, rows, obs)
            noise = torch.zeros(n, *noise.shape[1:]).index_copy_(0, rows, noise)
        with torch.no_grad():
            actions = step.act(obs.to(device), noise.to(device)).cpu().numpy()
        return [actions[i, 0] for i in ids]

    def _batch_move(self, ids: Sequence[int], actions: Sequence[np.ndarray]) -> list[tuple[np.ndarray, bool]]:
        """Every seed's agent moved by its action in one `batch_step` of the goal env (stateless; the
        seeds' envs are one configuration): [(its next configuration, whether it was blocked)]."""
        space = self.runners[0].env.single_action_space
        configs = np.stack([self.envs[i].inner.configuration for i in ids])
        # (what the env is given: elementwise, so one call serves every seed's row)
        moved, blocked = self.envs[ids[0]].inner.batch_step(configs, self._for_env(np.stack(actions), space))
        return [(moved[k], bool(blocked[k])) for k in range(len(ids))]

    def _update(self, owed: Mapping[int, tuple[int, dict]]) -> dict[int, Any]:
        """{seed index: (gradient steps, timesteps)} -> {seed index: (its learner results, seconds), or
        the error its update raised}."""
        if not owed:
            return {}
        t0 = time.perf_counter()
        try:
            results = self.updates.update(owed)
        except Exception as err:  # noqa: BLE001 - it fails every seed it held
            return dict.fromkeys(owed, err)
        seconds = time.perf_counter() - t0  # every seed waited for the whole stacked step
        return {i: (results[i], seconds) for i in owed}

    # ------------------------------------------------------------------ checkpoints
    def get_state(self) -> dict[str, Any]:
        """The stacked update's state (every seed's parameters, optimizer state and noise stream)."""
        return self.updates.get_state()

    def set_state(self, state: Mapping[str, Any]) -> None:
        self.updates.set_state(state)
