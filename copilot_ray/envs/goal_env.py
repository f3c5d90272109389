"""The goal-conditioned env contract: what CO-PILOT, its baselines, the planners and the evaluation rely
on, as a typing Protocol, and the sparse reward and termination every env shares.

Gymnasium-Robotics' convention plus what planning needs. `tests/test_goal_env.py` runs every registered
env through `contract_problems`, so a new env that misses a piece fails there, not hours into a sweep.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from gymnasium import spaces

OBSERVATION_KEYS = ("observation", "achieved_goal", "desired_goal")


@dataclass(frozen=True)
class GoalMetric:
    """`goal_distance` as data, for code that computes it elsewhere (HER's relabelled rewards on the
    learner's device): sqrt(sum_i (w_i * d_i)^2), d = b - a with the dims in `angle_dims` wrapped to
    [-pi, pi). `contract_problems` holds it equal to the env's own `goal_distance`."""

    weights: tuple[float, ...]
    angle_dims: tuple[int, ...] = ()

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """[N, d], [N, d] -> [N] (or [d], [d] -> scalar), in float64."""
        d = np.asarray(b, np.float64) - np.asarray(a, np.float64)
        for i in self.angle_dims:
            d[..., i] = (d[..., i] + np.pi) % (2 * np.pi) - np.pi
        return np.sqrt(((np.asarray(self.weights) * d) ** 2).sum(-1))


@runtime_checkable
class GoalEnv(Protocol):
    """A goal-conditioned env as this package uses it.

    Observations are dicts with OBSERVATION_KEYS; `reset(options={"start": s, "goal": g})` places the
    agent (an env with `goal_only_reset = True` also takes `{"goal": g}` as "same motion, new goal");
    `terminated` means the goal was reached; `info` carries `success` and `collision` (and may carry
    `failed`: something the agent cannot undo, and `dense_reward`). Batched methods take [N, goal_dim]
    arrays and return [N]; a single [goal_dim] row gives a scalar.
    """

    observation_space: spaces.Dict
    action_space: spaces.Box
    goal_space: spaces.Box  # where sub-goals live (the planner samples in it)
    goal_dim: int
    success_radius: float  # a goal is reached within this goal_distance
    goal_reward: float
    max_episode_steps: int

    @property
    def nominal_step_distance(self) -> float:
        """Furthest the agent moves in goal space in one step (turns step counts into distances)."""

    def goal_distance(self, a: np.ndarray, b: np.ndarray) -> Any: ...

    @property
    def goal_metric(self) -> GoalMetric:
        """`goal_distance` as data (its weights and wrapped angle dims)."""

    def segments_collide(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N]: whether the straight motion a -> b touches an obstacle (a collision check each)."""

    def is_free(self, config: np.ndarray) -> bool: ...

    def tasks(self, split: str) -> tuple[np.ndarray, np.ndarray]:
        """(starts, goals) [n, goal_dim] of the fixed `train`, `validation` or `test` set."""

    def compute_reward(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None
    ) -> Any: ...

    def compute_terminated(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None
    ) -> Any: ...

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict]: ...

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]: ...


class SparseGoalReward:
    """The sparse reward and termination of every env here (HER recomputes both for relabelled goals):
    `goal_reward` within `success_radius` of the goal, else 0; terminated there. Needs `goal_distance`,
    `success_radius` and `goal_reward` on the env."""

    goal_reward: float
    success_radius: float

    def compute_terminated(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None
    ) -> Any:
        """Whether the goal is reached: [N, d] -> bool [N]; [d] -> bool."""
        reached = self.goal_distance(achieved_goal, desired_goal) <= self.success_radius  # type: ignore[attr-defined]
        return bool(reached) if np.ndim(reached) == 0 else reached

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None) -> Any:
        """goal_reward within success_radius, else 0: [N, d] -> [N]; [d] -> float."""
        reward = np.where(self.compute_terminated(achieved_goal, desired_goal), self.goal_reward, 0.0)
        return float(reward) if np.ndim(reward) == 0 else reward


# Every name the Protocol declares (typing's own list is private before Python 3.12).
CONTRACT_MEMBERS = tuple(
    sorted({*GoalEnv.__annotations__, *(n for n in vars(GoalEnv) if not n.startswith("_"))})
)


def contract_problems(env: Any) -> list[str]:
    """What `env` (unwrapped) misses of the contract, one line each; [] when it keeps it. Checks the
    members and spaces, then one reset onto a validation task and one step."""
    missing = [name for name in CONTRACT_MEMBERS if not hasattr(env, name)]
    if missing:
        return [f"missing {', '.join(sorted(missing))}"]
    problems = []
    obs_space = env.observation_space
    if not isinstance(obs_space, spaces.Dict) or set(obs_space.spaces) != set(OBSERVATION_KEYS):
        return [f"observation_space must be a Dict of {OBSERVATION_KEYS}, got {obs_space}"]
    for key in ("achieved_goal", "desired_goal"):
        if obs_space[key].shape != (env.goal_dim,):
            problems.append(f"observation_space[{key!r}] has shape {obs_space[key].shape}, not (goal_dim,)")
    if env.goal_space.shape != (env.goal_dim,):
        problems.append(f"goal_space has shape {env.goal_space.shape}, not ({env.goal_dim},)")
    starts, goals = env.tasks("validation")
    if starts.shape != goals.shape or starts.shape[1:] != (env.goal_dim,):
        return problems + [
            f"tasks('validation') shapes {starts.shape}, {goals.shape}: not [n, goal_dim] each"
        ]
    obs, _ = env.reset(seed=0, options={"start": starts[0], "goal": goals[0]})
    if not np.allclose(obs["desired_goal"], goals[0], atol=1e-5):
        problems.append("reset(options={'start', 'goal'}) does not set desired_goal to the goal")
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    for key in ("success", "collision"):
        if key not in info:
            problems.append(f"step's info has no {key!r}")
    if bool(terminated) != bool(env.compute_terminated(obs["achieved_goal"], obs["desired_goal"], info)):
        problems.append("step's terminated disagrees with compute_terminated")
    both = np.stack([goals[0], starts[0]])
    batched = env.compute_reward(both, both[[0, 0]], None)
    if np.shape(batched) != (2,) or batched[0] != env.goal_reward or batched[1] != 0.0:
        problems.append(f"compute_reward on [2, goal_dim] gave {batched!r}, not [goal_reward, 0]")
    if not isinstance(env.compute_reward(goals[0], goals[0], None), float):
        problems.append("compute_reward on one [goal_dim] row does not give a float")
    pairs = (starts[:20], goals[:20]), (goals[:20], np.roll(goals[:20], 1, axis=0))
    if not all(np.allclose(env.goal_metric.distance(a, b), env.goal_distance(a, b)) for a, b in pairs):
        problems.append("goal_metric.distance disagrees with goal_distance on validation tasks")
    if np.shape(env.segments_collide(both, both[::-1])) != (2,):
        problems.append("segments_collide on [2, goal_dim] does not give [2]")
    if not env.is_free(starts[0]):
        problems.append("is_free is False at a validation task's start")
    return problems
