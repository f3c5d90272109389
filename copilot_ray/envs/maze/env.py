"""`GoalMazeEnv`: a goal-conditioned agent in a 1 x 1 maze (the paper's Maze, Section 4)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from copilot_ray.envs.env_config import bad_value, is_integer, is_number, merged_config
from copilot_ray.envs.goal_env import GoalMetric, SparseGoalReward
from copilot_ray.envs.task_sets import TASK_SETS, check_task_set, check_test_set, draw_task_sets

from .agents import AgentGeometry, PointMass
from .geometry import Obstacles
from .layouts import Layout, load_layout
from .render import render_maze
from .rigid_body import RigidBody
from .snake import Snake
from .tasks import SPLITS, check_body_fits, sample_task_pairs, split_rng

# Agent kinds (the maze env's `agent` argument); a new agent is an AgentGeometry and one line here.
AGENTS: dict[str, type[AgentGeometry]] = {"point": PointMass, "rigid": RigidBody, "snake": Snake}

# four-rooms: 67 % of straight test start->goal lines collide, yet no task needs more than two doorways.
DEFAULT_LAYOUT = "four-rooms"
# Chosen so that the mean shortest path on the default layout's test tasks takes >= 200 steps (the
# paper's ">= 200 steps on average"); `benchmarks/maze_geometry.py` prints the figure.
DEFAULT_SPEED = 0.0025

DEFAULTS: dict[str, Any] = {
    "layout": DEFAULT_LAYOUT,
    "speed": DEFAULT_SPEED,
    "success_radius": 0.025,
    "goal_reward": 1.0,
    "max_episode_steps": 1000,
    "num_train_tasks": 300,
    "num_validation_tasks": 100,
    "num_test_tasks": 100,
    "task_seed": 0,
    # Which tasks the test set holds: "original", or "fresh" (its own seed stream; envs/task_sets.py).
    "test_set": "original",
    "task_split": "train",
    "render_mode": None,
    "render_size": 256,
}


def _check_config(config: Mapping[str, Any]) -> dict[str, Any]:
    """Merge over DEFAULTS; reject unknown keys and bad values, naming the key and the value."""
    cfg = merged_config("maze", config, DEFAULTS)

    def bad(key: str, need: str) -> ValueError:
        return bad_value(cfg, key, need)

    if not isinstance(cfg["layout"], str | Path | Layout):
        raise bad("layout", "a built-in layout name or a path to a layout file")
    for key in ("speed", "success_radius"):
        if not (is_number(cfg[key]) and 0 < cfg[key] < 0.5):
            raise bad(key, "a number in (0, 0.5)")
    if not is_number(cfg["goal_reward"]):
        raise bad("goal_reward", "a finite number")
    for key in ("max_episode_steps", "num_train_tasks", "num_validation_tasks", "num_test_tasks"):
        if not (is_integer(cfg[key]) and cfg[key] > 0):
            raise bad(key, "a positive integer")
    if not (is_integer(cfg["task_seed"]) and cfg["task_seed"] >= 0):
        raise bad("task_seed", "a non-negative integer")
    if cfg["task_split"] not in SPLITS:
        raise bad("task_split", f"one of {', '.join(SPLITS)}")
    if (need := check_test_set(cfg["test_set"])) is not None:
        raise bad("test_set", need)
    if cfg["render_mode"] not in GoalMazeEnv.metadata["render_modes"] + [None]:
        raise bad("render_mode", f"None or one of {GoalMazeEnv.metadata['render_modes']}")
    if not (is_integer(cfg["render_size"]) and cfg["render_size"] >= 16):
        raise bad("render_size", "an integer >= 16")
    return cfg


class GoalMazeEnv(SparseGoalReward, gym.Env):
    """An agent moves through a maze of square obstacles in the unit square towards a goal configuration.

    A move whose straight motion would touch an obstacle or the border is blocked (the agent stays) and
    reported as `info["collision"]`. The episode terminates within `success_radius` of the goal;
    `info["success"]` additionally needs a collision-free episode. Truncation after `max_episode_steps`
    happens here (no TimeLimit wrapper) so that RLlib sees it.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, env_config: Mapping[str, Any] | None = None, *, agent: str = "point", **kwargs: Any):
        config = _check_config({**dict(env_config or {}), **kwargs})
        if agent not in AGENTS:
            raise ValueError(f"unknown maze agent {agent!r}; valid: {', '.join(AGENTS)}")
        self.config = config
        self.layout: Layout = load_layout(config["layout"])
        self.obstacles = Obstacles.from_layout(self.layout)
        self.agent_geometry: AgentGeometry = AGENTS[agent](speed=float(config["speed"]))
        self.success_radius = float(config["success_radius"])
        check_body_fits(
            self.agent_geometry, self.obstacles, self.success_radius, self.layout.name, self.layout.to_text()
        )
        self.goal_reward = float(config["goal_reward"])
        self.max_episode_steps = int(config["max_episode_steps"])
        self.render_mode = config["render_mode"]

        low, high = (b.astype(np.float32) for b in self.agent_geometry.bounds)
        self.goal_dim = self.agent_geometry.config_dim
        self.goal_space = spaces.Box(low, high, dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(low, high, dtype=np.float32),
                "achieved_goal": spaces.Box(low, high, dtype=np.float32),
                "desired_goal": spaces.Box(low, high, dtype=np.float32),
            }
        )
        n_act = self.agent_geometry.action_dim
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n_act,), dtype=np.float32)

        self._fixed: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._next_task: tuple[np.ndarray, np.ndarray] | None = None
        self._render_path: np.ndarray | None = None
        self._config_now = np.zeros(self.goal_dim)
        self._goal = np.zeros(self.goal_dim)
        self._steps = 0
        self._collisions = 0

    # --- planning interface -------------------------------------------------------------------------

    @property
    def nominal_step_distance(self) -> float:
        """Furthest the agent moves in goal space in one step (turns step counts into distances)."""
        return self.agent_geometry.nominal_step_distance

    def goal_distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """[N, d], [N, d] -> [N] (or [d], [d] -> scalar)."""
        return self.agent_geometry.distance(a, b)

    @property
    def goal_metric(self) -> GoalMetric:
        """The agent's configuration distance as data: its weights and wrapped angles."""
        geometry = self.agent_geometry
        return GoalMetric(tuple(float(w) for w in geometry.distance_weights), tuple(geometry.angle_dims))

    def segments_collide(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """[N, d], [N, d] -> bool [N]: the straight motion touches an obstacle or leaves the square."""
        return self.agent_geometry.motions_collide(self.obstacles, a, b)

    def collision_lengths(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """[N, d], [N, d] -> float [N]: how much of the straight motion is in collision (0: free or touching)."""
        return self.agent_geometry.motion_collision_lengths(self.obstacles, a, b)

    def is_free(self, config: np.ndarray) -> bool:
        """Whether the agent can stand at `config` [d] (inside the maze, touching nothing)."""
        return bool(
            self.agent_geometry.clearance(self.obstacles, np.asarray(config, np.float64)[None])[0] > 0.0
        )

    def sample_tasks(
        self, n: int, split: str = "train", seed: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(starts, goals) float32 [n, goal_dim], deterministic for (split, seed); seed defaults to task_seed."""
        seed = self.config["task_seed"] if seed is None else seed
        return self._sample(n, split_rng(split, seed))

    def tasks(self, split: str) -> tuple[np.ndarray, np.ndarray]:
        """The fixed task sets (`task_sets.TASK_SETS`): `train`, `validation` and `test`
        (num_<split>_tasks each), pairwise disjoint."""
        check_task_set(split)
        if not self._fixed:
            sizes = {name: self.config[f"num_{name}_tasks"] for name in TASK_SETS}
            self._fixed = draw_task_sets(self.sample_tasks, sizes, self.config["test_set"])
        starts, goals = self._fixed[split]
        return starts.copy(), goals.copy()

    def _sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        return sample_task_pairs(
            self.agent_geometry,
            self.obstacles,
            n,
            rng,
            margin=self.success_radius,
            min_separation=2.0 * self.success_radius,
        )

    # --- task control -------------------------------------------------------------------------------

    def _as_config(self, value: Any, key: str, must_be_free: bool = True) -> np.ndarray:
        arr = np.asarray(value, dtype=np.float32).astype(np.float64)
        if arr.shape != (self.goal_dim,) or not np.isfinite(arr).all():
            raise ValueError(f"{key} must be {self.goal_dim} finite numbers, got {value!r}")
        if must_be_free and self.agent_geometry.clearance(self.obstacles, arr[None])[0] <= 0.0:
            raise ValueError(f"{key} {arr.tolist()} lies in an obstacle or outside the maze")
        if not must_be_free and not self.goal_space.contains(arr.astype(np.float32)):
            raise ValueError(f"{key} {arr.tolist()} lies outside the goal space")
        return arr

    def set_task(self, start: Any, goal: Any) -> None:
        """Use (start, goal) for the next reset and every later one, until changed or cleared."""
        self._next_task = (self._as_config(start, "start"), self._as_config(goal, "goal", must_be_free=False))

    def clear_task(self) -> None:
        """Go back to drawing tasks from `task_split`."""
        self._next_task = None

    def set_render_path(self, points: Any) -> None:
        """Sub-goals [P, goal_dim] drawn as a polyline by `render()`; None clears."""
        self._render_path = (
            None if points is None else np.asarray(points, dtype=np.float64).reshape(-1, self.goal_dim)
        )

    # --- gymnasium API ------------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"start", "goal"}
        if unknown:
            raise ValueError(f"unknown reset option {sorted(unknown)[0]!r}; valid: start, goal")
        if options:
            if set(options) != {"start", "goal"}:
                raise ValueError("reset options need both 'start' and 'goal'")
            # A goal may lie in an obstacle: a planner's sub-goal can, and then it is simply unreachable.
            start = self._as_config(options["start"], "start")
            goal = self._as_config(options["goal"], "goal", must_be_free=False)
        elif self._next_task is not None:
            start, goal = self._next_task
        elif self.config["task_split"] == "uniform":
            starts, goals = self._sample(1, self.np_random)
            start, goal = starts[0].astype(np.float64), goals[0].astype(np.float64)
        else:
            starts, goals = self.tasks(self.config["task_split"])
            i = int(self.np_random.integers(len(starts)))
            start, goal = starts[i].astype(np.float64), goals[i].astype(np.float64)
        self._config_now, self._goal = start.copy(), goal.copy()
        self._steps, self._collisions = 0, 0
        return self._obs(), self._info(collision=False)

    def step(self, action: Any):
        # Round to float32 before the collision check, so the stored position is exactly the checked one.
        proposed = self.agent_geometry.step(self._config_now, action).astype(np.float32).astype(np.float64)
        collision = bool(self.segments_collide(self._config_now[None], proposed[None])[0])
        return self.step_to(self._config_now if collision else proposed, collision)

    def step_to(self, config: np.ndarray, collision: bool):
        """What `step` does after its motion, with the motion given: the agent now at `config` (where
        `batch_step` moved it; its old configuration when `collision` blocked it). A seed stack moves
        every seed's agent in one `batch_step` and finishes each seed's step here."""
        if collision:
            self._collisions += 1
        self._config_now = np.array(config, np.float64)
        self._steps += 1
        obs = self._obs()
        info = self._info(collision=collision)
        terminated = self.compute_terminated(obs["achieved_goal"], obs["desired_goal"], info)
        reward = float(self.goal_reward) if terminated else 0.0  # compute_reward's, its distance once
        truncated = not terminated and self._steps >= self.max_episode_steps
        return obs, reward, terminated, truncated, info

    @property
    def configuration(self) -> np.ndarray:
        """The agent's configuration now (what `batch_step` takes)."""
        return self._config_now

    def batch_step(self, configs: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`step`'s motion for N agents at once, without touching this env's own state:
        configurations [N, d] (float32-exact), actions [N, a] -> (next configurations, collided [N]).
        A blocked move leaves the agent where it was, as `step` does. The maze's whole state is the
        configuration (observation = achieved goal), so lockstep evaluation rollouts keep arrays instead
        of N envs."""
        configs = np.asarray(configs, np.float64)
        proposed = self.agent_geometry.step_batch(configs, actions).astype(np.float32).astype(np.float64)
        collided = np.asarray(self.segments_collide(configs, proposed), bool)
        return np.where(collided[:, None], configs, proposed), collided

    def _obs(self) -> dict[str, np.ndarray]:
        pos = self._config_now.astype(np.float32)
        return {
            "observation": pos.copy(),
            "achieved_goal": pos.copy(),
            "desired_goal": self._goal.astype(np.float32),
        }

    def _info(self, collision: bool) -> dict[str, Any]:
        distance = float(self.goal_distance(self._config_now, self._goal))
        return {
            "collision": collision,
            "success": bool(distance <= self.success_radius and self._collisions == 0),
            "num_collisions": self._collisions,
            "distance": distance,
        }

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        paths = [] if self._render_path is None else [self._render_path]
        return render_maze(
            self, agent=self._config_now, goal=self._goal, paths=paths, size=self.config["render_size"]
        )


def shortest_path_lengths(env: gym.Env, starts: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """float [N]: exact shortest collision-free path length for each (start, goal); inf if unreachable."""
    maze = env.unwrapped
    return maze.agent_geometry.shortest_path_lengths(maze.obstacles, starts, goals)


def make_maze_point(**env_config: Any) -> GoalMazeEnv:
    return GoalMazeEnv(env_config, agent="point")


def make_maze_rigid(**env_config: Any) -> GoalMazeEnv:
    return GoalMazeEnv(env_config, agent="rigid")


def make_maze_snake(**env_config: Any) -> GoalMazeEnv:
    return GoalMazeEnv(env_config, agent="snake")
