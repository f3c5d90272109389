"""Success rate on held-out tasks: the agent following the planner's path, and the agent alone.

`AgentEvaluation` is the measuring protocol every agent-based method goes through (GoalSAC and its
relatives, PPO, HRL): the same validation and test tasks, the same cadence, the same action modes and
sampling seeds, the same success, return and area definitions, the same metric names. A method brings its
rollouts (its policies on given tasks, in lockstep); the figures are computed here, once.

Rollouts run N copies of the goal env in lockstep on the driver, with one batched policy call per
step, so evaluating 100 test tasks costs a few seconds and needs no env runner.

Every evaluation runs the policy twice: with deterministic actions (tanh of the Gaussian's mean) and
with sampled ones. A blocked move leaves the point where it was, so a deterministic policy whose mean
points into a wall repeats that move until time runs out, where a sampled one slides off. Success needs
the goal reached without any collision; "reached" counts reaching it at all.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from copilot_ray.envs import make
from copilot_ray.envs.continuation import reset_toward
from copilot_ray.envs.goal_observation import flat_observation
from copilot_ray.keys import (
    EVAL_ACTIONS,
    EVAL_PREFIX,
    EVAL_RETURN,
    EVAL_SUCCESS,
    EVAL_SUCCESS_AUC,
    REACHED_DIRECT,
    REACHED_PLANNED,
    SUBGOALS_REACHED_PLANNED,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    eval_by_action,
    eval_leaf,
    validation_key,
)
from copilot_ray.planning.path_metrics import PathScores, score_paths
from copilot_ray.planning.subgoal_tree import path_indices

Policy = Callable[[np.ndarray], np.ndarray]
# The task sets every evaluation runs on: validation (what searchers and probes read, under
# copilot/validation/) and test (what reports show, under copilot/eval/).
EVAL_SPLITS = ("validation", "test")


class EvaluationSchedule:
    """When an algorithm evaluates: every `every_iterations` iterations, or, with `every_env_steps` > 0,
    at the end of each iteration that passes another multiple of that many env steps (one cadence for
    methods whose iterations differ in size). Checkpointed with `get_state` / `set_state`."""

    def __init__(self, every_iterations: int, every_env_steps: int = 0):
        self.every_iterations = int(every_iterations)
        self.every_env_steps = int(every_env_steps)
        self._last_bucket = 0  # env steps // every_env_steps at the last evaluation

    def due(self, iteration: int, env_steps: int, whole: bool = True) -> bool:
        """Whether to evaluate after iteration `iteration` (1-based) ending at `env_steps`. An iteration
        that is not `whole` (a stop cut it short, its batch left to the next) is evaluated only at an
        env-step point: on the iterations cadence the iteration that finishes its batch is, where an
        uninterrupted run evaluates too."""
        if self.every_env_steps > 0:
            if self.point_passed(env_steps):
                self._last_bucket = int(env_steps) // self.every_env_steps
                return True
            return False
        return whole and bool(self.every_iterations) and iteration % self.every_iterations == 0

    def point_passed(self, env_steps: int) -> bool:
        """Whether `env_steps` is past an env-step evaluation point not evaluated at yet (False on the
        iterations cadence). Asks only: an algorithm whose iterations hold several rounds ends one early
        where this turns True, so its evaluations keep the cadence."""
        return self.every_env_steps > 0 and int(env_steps) // self.every_env_steps > self._last_bucket

    def get_state(self) -> dict[str, int]:
        return {"last_bucket": self._last_bucket}

    def set_state(self, state: dict[str, int]) -> None:
        self._last_bucket = int(state.get("last_bucket", 0))


class SuccessCurve:
    """One split's success at each evaluation so far, and the area under that curve normalised by its
    env-step span (trapezoid; with one evaluation, its value): `keys.EVAL_SUCCESS_AUC`."""

    def __init__(self):
        self.steps: list[float] = []
        self.values: list[float] = []

    def add(self, env_steps: int, value: float) -> float:
        """Records an evaluation and returns the normalised area so far."""
        self.steps.append(float(env_steps))
        self.values.append(float(value))
        return self.auc()

    def auc(self) -> float:
        if not self.values:
            return float("nan")
        span = self.steps[-1] - self.steps[0]
        if span <= 0:
            return float(np.mean(self.values))
        return float(np.trapezoid(self.values, self.steps) / span)

    def get_state(self) -> dict[str, list[float]]:
        return {"steps": list(self.steps), "values": list(self.values)}

    def set_state(self, state: dict[str, list[float]]) -> None:
        self.steps, self.values = list(state.get("steps", [])), list(state.get("values", []))


DETERMINISTIC, SAMPLED = EVAL_ACTIONS
# One action mode's rollouts on one task set, as shares of its tasks, by `eval_leaf` name: success_direct
# and reached_direct always; success_planned, reached_planned (and subgoals_reached_planned) where the
# agent follows a plan.
ActionFigures = Mapping[str, float]


class AgentEvaluation:
    """The one measuring protocol of every agent-based method (see the module docstring).

    Tasks: the first `num_tasks` of the env's validation and test sets (as many of each: the fewer of
    the two sets' sizes bounds it). Cadence: `EvaluationSchedule(every_iterations, every_env_steps)`.
    Actions: the headline `eval_action` on both sets, and on the test set the other mode too; sampled
    actions draw from their own stream seeded run seed + iteration (`action_seeds`), so that an evaluation
    never moves training's randomness and methods at the same seed and iteration sample alike. Figures
    (`figures`): success needs the goal reached with no collision; the headline `copilot/eval/success` is
    the agent following its plan (alone where it has none); the return is `task_reward` (R) x the goals
    reached along the plan; the area under each set's success curve so far (`SuccessCurve`).
    Checkpointed with `get_state` / `set_state`."""

    def __init__(
        self,
        env,
        num_tasks: int,
        eval_action: str,
        every_iterations: int,
        every_env_steps: int = 0,
        task_reward: float = 1.0,
    ):
        if eval_action not in EVAL_ACTIONS:
            raise ValueError(f"eval_action={eval_action!r} is invalid: use one of {EVAL_ACTIONS}")
        sets = {split: env.tasks(split) for split in EVAL_SPLITS}
        self.num_tasks = min(int(num_tasks), *(len(starts) for starts, _ in sets.values()))
        self.tasks = {split: (s[: self.num_tasks], g[: self.num_tasks]) for split, (s, g) in sets.items()}
        self.eval_action = eval_action
        self.schedule = EvaluationSchedule(every_iterations, every_env_steps)
        self.curves = {split: SuccessCurve() for split in EVAL_SPLITS}
        self.task_reward = float(task_reward)

    def action_seeds(self, split: str, run_seed: int | None, iteration: int) -> dict[str, int | None]:
        """The action modes `split` is evaluated with, the headline first, each with its sampling seed
        (None: deterministic actions); the validation set gets the headline mode only."""
        seeds = {DETERMINISTIC: None, SAMPLED: (0 if run_seed is None else int(run_seed)) + int(iteration)}
        if split != "test":
            return {self.eval_action: seeds[self.eval_action]}
        return {self.eval_action: seeds[self.eval_action], **seeds}

    def figures(self, split: str, by_action: Mapping[str, ActionFigures], env_steps: int) -> dict[str, float]:
        """One set's figures under their metric names (`copilot/eval/...` for the test set, the
        validation twins for the validation set): the headline mode's figures, the common success, its
        area so far, the return; on the test set every mode's figures too (`copilot/eval/<mode>/...`).
        A mode without a plan's figures is its direct ones (the agent alone is what it follows)."""
        full = {action: _with_plan(values) for action, values in by_action.items()}
        headline = full[self.eval_action]
        success = headline[eval_leaf(SUCCESS_PLANNED)]
        named = {EVAL_PREFIX + leaf: value for leaf, value in headline.items()}
        named[EVAL_SUCCESS] = success
        named[EVAL_SUCCESS_AUC] = self.curves[split].add(env_steps, success)
        named[EVAL_RETURN] = self.task_reward * headline[eval_leaf(REACHED_PLANNED)]
        if split != "test":
            return {validation_key(key): value for key, value in named.items()}
        for action, values in full.items():
            for leaf, value in values.items():
                named[eval_by_action(EVAL_PREFIX + leaf, action)] = value
        return named

    def get_state(self) -> dict[str, Any]:
        return {
            "eval_schedule": self.schedule.get_state(),
            "success_curves": {split: c.get_state() for split, c in self.curves.items()},
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        self.schedule.set_state(state.get("eval_schedule", {}))
        for split, curve in state.get("success_curves", {}).items():
            self.curves[split].set_state(curve)


def _with_plan(values: ActionFigures) -> dict[str, float]:
    """A mode's figures with the planned ones filled from the direct ones where there is no plan."""
    out = dict(values)
    for planned, direct in ((SUCCESS_PLANNED, SUCCESS_DIRECT), (REACHED_PLANNED, REACHED_DIRECT)):
        out.setdefault(eval_leaf(planned), out[eval_leaf(direct)])
    return out


class ModulePolicy:
    """Actions of an RLModule's Gaussian: its mean, or (`sampled=True`) a sample, squashed to [-1, 1]
    by tanh (SAC's squashed Gaussian, `squash="tanh"`) or clipped (`squash="clip"`: PPO's plain
    Gaussian, whose actions the env clips).

    Not `dist.to_deterministic()`: for RLlib's TorchSquashedGaussian that returns the *unsquashed*
    mean, which clipped to [-1, 1] turns every confident action into a full-speed one.
    """

    def __init__(self, module, sampled: bool = False, seed: int = 0, squash: str = "tanh"):
        if squash not in ("tanh", "clip"):
            raise ValueError(f"squash={squash!r} is invalid: use 'tanh' or 'clip'")
        self.module = module
        self.sampled = sampled
        self.squash = squash
        self.generator = torch.Generator().manual_seed(seed)

    @torch.no_grad()
    def __call__(self, obs: np.ndarray) -> np.ndarray:
        out = self.module.forward_inference({"obs": torch.as_tensor(obs, dtype=torch.float32)})
        mean, log_std = out["action_dist_inputs"].chunk(2, dim=-1)
        if self.sampled:
            noise = torch.randn(mean.shape, generator=self.generator)
            mean = mean + noise * torch.exp(log_std)
        return (torch.tanh(mean) if self.squash == "tanh" else torch.clamp(mean, -1.0, 1.0)).numpy()


@dataclass
class WaypointRollout:
    success: np.ndarray  # [N] reached the last waypoint with no collision
    reached_final: np.ndarray  # [N] reached the last waypoint
    collided: np.ndarray  # [N]
    total_steps: np.ndarray  # [N]
    subtask_steps: np.ndarray  # [N, P-1]
    subtask_reached: np.ndarray  # [N, P-1]


class _EnvRollouts:
    """N copies of any goal env, stepped one after another (one batched policy call per step)."""

    def __init__(self, envs: list):
        self.envs = envs

    def reset(self, i: int, start: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
        return self.envs[i].reset(options={"start": start, "goal": goal})[0]

    def retarget(self, i: int, position: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
        return reset_toward(self.envs[i], position, goal)[0]

    def step(self, ids: np.ndarray, actions: np.ndarray, goals: np.ndarray):
        """(observations, achieved goals, reached, collided, failed) of envs `ids` after `actions`."""
        obs, achieved = [], []
        n = len(ids)
        reached, collided, failed = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        for j, i in enumerate(ids):
            o, _, done, _, info = self.envs[i].step(actions[j])
            obs.append(o["observation"])
            achieved.append(o["achieved_goal"])
            reached[j] = bool(done)
            collided[j] = bool(info.get("collision", False))
            failed[j] = bool(info.get("failed", False))
        return np.stack(obs), np.stack(achieved), reached, collided, failed


class _BatchRollouts:
    """N agents of one goal env whose whole state is its configuration (the maze: `batch_step`),
    stepped as arrays: one call per step for all of them, no env objects per task."""

    def __init__(self, env, n: int):
        self.env = env
        self.position = np.zeros((n, env.goal_dim))

    def reset(self, i: int, start: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
        self.position[i] = np.asarray(start, np.float32)
        return self._obs(i)

    def retarget(self, i: int, position: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
        return self._obs(i)  # the agent stays where it is: the same as a reset there

    def _obs(self, i: int) -> dict[str, np.ndarray]:
        pos = self.position[i].astype(np.float32)
        return {"observation": pos, "achieved_goal": pos}

    def step(self, ids: np.ndarray, actions: np.ndarray, goals: np.ndarray):
        moved, collided = self.env.batch_step(self.position[ids], actions)
        self.position[ids] = moved
        achieved = moved.astype(np.float32)
        reached = np.asarray(self.env.compute_terminated(achieved, goals.astype(np.float32)), bool)
        return achieved, achieved, reached, collided, np.zeros(len(ids), bool)


def rollouts_for(envs: list):
    """Lockstep rollouts over `envs` (copies of one goal env): as arrays where the env offers
    `batch_step`, else env by env."""
    inner = envs[0].unwrapped
    if hasattr(inner, "batch_step"):
        return _BatchRollouts(inner, len(envs))
    return _EnvRollouts(envs)


def follow_waypoints(
    envs: list,
    policy: Policy,
    waypoints: np.ndarray,
    tau_max: int | np.ndarray,
    with_delta: bool = False,
    max_total_steps: int | None = None,
) -> WaypointRollout:
    """Each env starts at waypoints[i, 0] and heads for waypoints[i, 1], [i, 2], ... in turn.

    A sub-task ends when its waypoint is reached or after `tau_max` steps (an int, or per task and
    waypoint: broadcastable to [N, P - 1]); the next one starts from wherever the agent stopped
    (`reset_toward`: an Ant keeps its motion). `with_delta`: the policy also sees waypoint - position
    (agent_input="state_goal_delta"). `max_total_steps`: a budget for the whole path (the rollout stops
    there, the rest of its waypoints unreached); so does a failure the agent cannot undo
    (`info["failed"]`: a flipped Ant, a fallen walker). Success needs the last waypoint reached with no
    collision on the way: a collision on an early sub-goal fails the rollout.
    """
    n, p, _ = waypoints.shape
    limits = np.broadcast_to(np.asarray(tau_max, np.int64), (n, p - 1))
    budget = np.iinfo(np.int64).max if max_total_steps is None else int(max_total_steps)
    rollouts = rollouts_for(envs)
    obs = np.zeros((n, envs[0].observation_space["observation"].shape[0]), np.float32)
    pos = waypoints[:, 0].copy()
    target = np.ones(n, np.int64)
    steps_in = np.zeros(n, np.int64)
    sub_steps = np.zeros((n, p - 1), np.int64)
    sub_reached = np.zeros((n, p - 1), bool)
    collided = np.zeros(n, bool)
    total = np.zeros(n, np.int64)
    for i in range(n):
        o = rollouts.reset(i, waypoints[i, 0], waypoints[i, 1])
        obs[i], pos[i] = o["observation"], o["achieved_goal"]
    active = np.ones(n, bool)
    while active.any():
        ids = np.flatnonzero(active)
        goals = waypoints[ids, target[ids]]
        actions = policy(flat_observation(obs[ids], goals, pos[ids] if with_delta else None))
        obs[ids], pos[ids], reached, hit, failed = rollouts.step(ids, actions, goals)
        collided[ids] |= hit
        steps_in[ids] += 1
        total[ids] += 1
        # Out of budget, or a failure the agent cannot undo (a flipped Ant): the rollout ends.
        over = (total[ids] >= budget) | failed
        ended = reached | (steps_in[ids] >= limits[ids, target[ids] - 1]) | over
        for j in np.flatnonzero(ended):
            i = ids[j]
            t = target[i] - 1
            sub_steps[i, t], sub_reached[i, t] = steps_in[i], reached[j]
            steps_in[i] = 0
            target[i] += 1
            if target[i] >= p or over[j]:
                active[i] = False
            else:
                o = rollouts.retarget(i, pos[i], waypoints[i, target[i]])
                obs[i], pos[i] = o["observation"], o["achieved_goal"]
    reached_final = sub_reached[:, -1]
    return WaypointRollout(reached_final & ~collided, reached_final, collided, total, sub_steps, sub_reached)


@dataclass
class CopilotEvaluation:
    # {"deterministic": {...}, "sampled": {...}}, each with success_planned, success_direct,
    # reached_planned, reached_direct (shares of the test tasks), subgoals_reached_planned
    by_action: dict[str, dict[str, float]]
    plan_collision_free: float
    plan_scores: PathScores  # the finest paths (mean trees) scored as motion plans
    trees: np.ndarray | None  # [n_tree, 2^K + 1, d] deterministic trees of the first test tasks
    tree_subtask_steps: np.ndarray | None  # [n_tree, K + 1, 2^K], -1 where layer k has no sub-task
    tree_subtask_reached: np.ndarray | None

    def headline(self, action: str) -> dict[str, float]:
        return self.by_action[action]


def evaluate_copilot(
    *,
    goal_env_id: str,
    goal_env_config: Mapping[str, Any],
    policies: Mapping[str, Policy],
    planner,
    starts: np.ndarray,
    goals: np.ndarray,
    depth: int,
    tau_max: int,
    tree_tasks: int = 0,
    tree_policy: str | None = None,
    step_limit_of: Callable[[int], int] | None = None,
    with_delta: bool = False,
    planned_total_steps: int | None = None,
    hop_limits: Callable[[np.ndarray], np.ndarray] | None = None,
) -> CopilotEvaluation:
    """Success of each policy in `policies` (e.g. deterministic and sampled actions) on the tasks.

    Planned: the agent follows the planner's finest path (mean tree), `step_limit_of(K)` steps per
    sub-goal (default tau_max); direct: the agent alone, with the step budget of the finest plan,
    tau_max * 2^K. The trees of the first `tree_tasks` tasks are traversed layer by layer with
    `policies[tree_policy]` (default: the first policy) for the sub-goal tree figure.
    `planner`: anything with `sample(starts, goals, deterministic=True) -> [N, P, d]` waypoints (a
    SoRB graph too); `hop_limits(waypoints)` -> [N, P - 1] replaces `step_limit_of(K)` per task and hop
    where given (SoRB: a task its graph cannot route gets the whole budget for its one hop). A planned
    rollout never takes more steps than the task's budget, tau_max * 2^K (the direct one's), nor more
    than `planned_total_steps` when that is smaller. Without a planner the planned rollout is the direct
    one when their budgets agree (run once).
    """

    step_limit_of = step_limit_of or (lambda k: tau_max)
    direct_budget = tau_max * 2**depth  # the agent alone gets the finest plan's whole budget
    planned_cap = direct_budget if planned_total_steps is None else min(planned_total_steps, direct_budget)
    n = len(starts)
    first = make(goal_env_id, **dict(goal_env_config))
    # An env that steps many agents as arrays (batch_step) needs one instance, not one per task.
    shared = hasattr(first.unwrapped, "batch_step")
    envs = (
        [first] * n
        if shared
        else [first] + [make(goal_env_id, **dict(goal_env_config)) for _ in range(n - 1)]
    )
    # depth 0: no planner, the "plan" is the task itself.
    trees = (
        np.stack([starts, goals], axis=1)
        if planner is None
        else planner.sample(starts, goals, deterministic=True)
    )
    limits = step_limit_of(depth) if hop_limits is None else hop_limits(trees)
    by_action = {}
    for name, policy in policies.items():
        planned = follow_waypoints(envs, policy, trees, limits, with_delta, max_total_steps=planned_cap)
        if planner is None and np.all(np.asarray(limits) == direct_budget):
            direct = planned  # the same rollout
        else:
            direct = follow_waypoints(
                envs, policy, np.stack([starts, goals], axis=1), direct_budget, with_delta
            )
        by_action[name] = {
            eval_leaf(SUCCESS_PLANNED): float(planned.success.mean()),
            eval_leaf(SUCCESS_DIRECT): float(direct.success.mean()),
            eval_leaf(REACHED_PLANNED): float(planned.reached_final.mean()),
            eval_leaf(REACHED_DIRECT): float(direct.reached_final.mean()),
            # share of the finest path's sub-goals reached: how far along the plan the agent gets
            eval_leaf(SUBGOALS_REACHED_PLANNED): float(planned.subtask_reached.mean()),
        }
    policy = policies[tree_policy or next(iter(policies))]
    geometry = envs[0].unwrapped
    a = trees[:, :-1].reshape(-1, trees.shape[-1])
    b = trees[:, 1:].reshape(-1, trees.shape[-1])
    plan_free = ~geometry.segments_collide(a, b).reshape(n, -1).any(axis=1)
    plan_scores = score_paths(geometry, trees, goals)

    tree_steps = tree_reached = kept = None
    if tree_tasks:
        kept = trees[:tree_tasks]
        tree_steps = -np.ones((tree_tasks, depth + 1, 2**depth), np.int64)
        tree_reached = np.zeros((tree_tasks, depth + 1, 2**depth), bool)
        for k in range(depth + 1):
            path = kept[:, path_indices(depth, k)]
            r = follow_waypoints(envs[:tree_tasks], policy, path, step_limit_of(k), with_delta)
            tree_steps[:, k, : 2**k] = r.subtask_steps
            tree_reached[:, k, : 2**k] = r.subtask_reached
    for env in {id(e): e for e in envs}.values():
        env.close()
    return CopilotEvaluation(
        by_action=by_action,
        plan_collision_free=float(plan_free.mean()),
        plan_scores=plan_scores,
        trees=kept,
        tree_subtask_steps=tree_steps,
        tree_subtask_reached=tree_reached,
    )
