"""`GoalAntMazeEnv`: MuJoCo's Ant quadruped (8-dim torques) navigating a maze (the paper's Fig. 2c/2d).

Built on Gymnasium-Robotics' AntMaze (v5): its maze maps, the MuJoCo model it writes for a map (walls as
boxes of `maze_size_scaling` metres) and its Ant. This class adds what CO-PILOT and the baselines need
from every goal env here (the 1 x 1 maze's interface):

* goal = the torso's (x, y) in the maze plane (metres); `observation` = the Ant's full state, torso
  (x, y) included (29 numbers: positions then velocities, no contact forces), so the goal-conditioned
  agent knows where it is without the goal delta;
* fixed, seeded task sets (`num_train_tasks` 50 / `num_test_tasks` 10, the paper's; `num_validation_tasks`
  10 for tuning) of (s0, g) pairs in
  free space, connected, at least `min_task_distance` apart;
* the planner's model of the Ant is a point in the plane among the walls grown by `wall_margin`
  (`segments_collide` / `collision_lengths` are exact against those boxes, as the point maze's are);
* a wall contact (any Ant geom touching a wall) is `info["collision"]`; a flip (the torso's up axis
  pointing below the horizon) is `info["failed"]` (and a collision) and truncates the episode, since the
  Ant cannot right itself ("without self-rotation and collisions to the wall"); `info["success"]` needs
  the goal reached with neither;
* `reset(options={"goal": g})` (`goal_only_reset`) keeps the Ant's physical state and only swaps the goal,
  so consecutive sub-tasks of a traversal continue one motion; a flipped Ant is stood up where it lies.

Rendering (`render_mode="rgb_array"`): MuJoCo's off-screen renderer from above the maze, with the goal
and the planned sub-goals (`set_render_path`) as markers; it needs an OpenGL backend chosen before
MuJoCo is imported: `MUJOCO_GL=egl` (GPU or Mesa's EGL) or `MUJOCO_GL=osmesa` (software).
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from copilot_ray.envs.env_config import bad_value, is_integer, is_number, merged_config
from copilot_ray.envs.goal_env import GoalMetric, SparseGoalReward
from copilot_ray.envs.maze.agents import PointMass
from copilot_ray.envs.maze.geometry import Obstacles, merge_cells
from copilot_ray.envs.maze.tasks import SPLITS, sample_task_pairs, split_rng
from copilot_ray.envs.task_sets import TASK_SETS, check_task_set, check_test_set, draw_task_sets

# The package prints a notice about its unrelated Adroit envs to stderr on import.
with contextlib.redirect_stderr(io.StringIO()):
    import gymnasium_robotics.envs.maze.maps as maps
    from gymnasium_robotics.envs.maze.ant_maze_v5 import AntMazeEnv

# Map names -> Gymnasium-Robotics' maps (1 = wall, 0 = free; rows from the top). The paper's Fig. 2c is a
# small maze; "u-maze" is the standard small one, "medium" and "large" the D4RL ones.
MAPS: dict[str, list[list[int]]] = {
    "u-maze": maps.U_MAZE,
    "medium": maps.MEDIUM_MAZE,
    "large": maps.LARGE_MAZE,
}
CELL_SIZE = 4.0  # metres per map cell (AntMaze's maze_size_scaling)
# One env step is 5 MuJoCo steps of 0.01 s. A good walking Ant covers about 1 m/s, so 0.05 m per step:
# the conversion between planner distances and agent steps (time-cost model, reach diagnostics).
NOMINAL_STEP_DISTANCE = 0.05
WALL_TOP = 2.0  # metres: AntMaze's walls are maze_height 0.5 x maze_size_scaling 4 high

DEFAULTS: dict[str, Any] = {
    "map": "u-maze",
    "success_radius": 0.45,  # AntMaze's own (in its code; its docs say 0.5)
    "goal_reward": 1.0,
    "wall_margin": 0.5,  # metres the planner keeps the torso from walls (the Ant's legs reach ~0.4 m)
    "min_task_distance": CELL_SIZE,  # s0 and g at least one cell apart
    "max_episode_steps": 1000,
    "num_train_tasks": 50,
    "num_validation_tasks": 10,
    "num_test_tasks": 10,
    "task_seed": 0,
    # Which tasks the test set holds: "original", or "fresh" (its own seed stream; envs/task_sets.py).
    "test_set": "original",
    "task_split": "train",
    "render_mode": None,
    "render_size": 256,
}


def _check_config(config: Mapping[str, Any]) -> dict[str, Any]:
    """Merge over DEFAULTS; reject unknown keys and bad values, naming the key and the value."""
    cfg = merged_config("ant-maze", config, DEFAULTS)

    def bad(key: str, need: str) -> ValueError:
        return bad_value(cfg, key, need)

    if cfg["map"] not in MAPS:
        raise bad("map", f"one of {', '.join(MAPS)}")
    for key in ("success_radius", "min_task_distance"):
        if not (is_number(cfg[key]) and cfg[key] > 0):
            raise bad(key, "a positive number (metres)")
    if not (is_number(cfg["wall_margin"]) and 0 <= cfg["wall_margin"] < CELL_SIZE / 2):
        raise bad("wall_margin", f"a number in [0, {CELL_SIZE / 2:g}) (metres)")
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
    if cfg["render_mode"] not in (None, "rgb_array"):
        raise bad("render_mode", "None or 'rgb_array'")
    if not (is_integer(cfg["render_size"]) and cfg["render_size"] >= 16):
        raise bad("render_size", "an integer >= 16")
    return cfg


def wall_boxes(grid: np.ndarray, cell: float = CELL_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) [boxes, 2] in metres of a map's walls (1-cells merged into few rectangles), centred as
    AntMaze centres its map: x grows with the column, y with decreasing row."""
    rows, cols = grid.shape
    rects = np.array(merge_cells(grid.astype(bool)), np.float64).reshape(-1, 4)
    r0, c0, r1, c1 = rects.T
    lo = np.stack([c0 * cell - cols * cell / 2, rows * cell / 2 - r1 * cell], axis=1)
    hi = np.stack([c1 * cell - cols * cell / 2, rows * cell / 2 - r0 * cell], axis=1)
    return lo, hi


class GoalAntMazeEnv(SparseGoalReward, gym.Env):
    """The Ant in a maze towards a goal position (module docstring). Truncates after
    `max_episode_steps` or a flip; terminates on reaching the goal."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}
    goal_only_reset = True  # reset(options={"goal": g}) continues the motion with a new goal

    def __init__(self, env_config: Mapping[str, Any] | None = None, **kwargs: Any):
        cfg = _check_config({**dict(env_config or {}), **kwargs})
        self.config = cfg
        self.map_name = cfg["map"]
        self.grid = np.array(MAPS[self.map_name], dtype=np.int64)
        self._maze_env = AntMazeEnv(
            maze_map=MAPS[self.map_name],
            continuing_task=False,
            include_cfrc_ext_in_observation=False,
        )
        self._ant = self._maze_env.ant_env
        model = self._ant.model
        self._torso = model.body("torso").id
        names = [model.geom(i).name for i in range(model.ngeom)]
        self._wall_geom = np.array([n.startswith("block_") for n in names])
        self._ant_geom = model.geom_bodyid > 0  # every geom on a body (the walls and floor are the world's)
        self._target_site = model.site("target").id

        self.walls_lo, self.walls_hi = wall_boxes(self.grid)
        rows, cols = self.grid.shape
        half = np.array([cols, rows], np.float64) * CELL_SIZE / 2
        region = (-half, half)
        m = float(cfg["wall_margin"])
        # The planner's world: the torso is a point, walls grown by the margin.
        self.obstacles = Obstacles(self.walls_lo - m, self.walls_hi + m, region)
        self.agent_geometry = PointMass(NOMINAL_STEP_DISTANCE, bounds=region)
        self.success_radius = float(cfg["success_radius"])
        self.goal_reward = float(cfg["goal_reward"])
        self.max_episode_steps = int(cfg["max_episode_steps"])
        self.render_mode = cfg["render_mode"]

        self.goal_dim = 2
        self.goal_space = spaces.Box(region[0].astype(np.float32), region[1].astype(np.float32))
        n_obs = self._ant.observation_space.shape[0]
        inf = np.full(n_obs, np.inf, np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-inf, inf, dtype=np.float32),
                "achieved_goal": self.goal_space,
                "desired_goal": self.goal_space,
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=self._ant.action_space.shape, dtype=np.float32)
        self._fixed: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._goal = np.zeros(2)
        self._obs = np.zeros(n_obs)
        self._steps = 0
        self._collisions = 0
        self._failed = False
        self._started = False
        self._render_path: np.ndarray | None = None
        self._renderer = None

    # --- planning interface (as the point maze's) ------------------------------------------------
    @property
    def nominal_step_distance(self) -> float:
        return NOMINAL_STEP_DISTANCE

    goal_metric = GoalMetric((1.0, 1.0))  # goal_distance as data: plain Euclidean in the plane

    def goal_distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """[N, 2], [N, 2] -> [N] (or [2], [2] -> scalar): distance in the maze plane."""
        return np.linalg.norm(np.asarray(b, np.float64) - np.asarray(a, np.float64), axis=-1)

    def segments_collide(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N]: the straight torso path a -> b comes within `wall_margin` of a wall."""
        return self.obstacles.segments_collide(a, b)

    def collision_lengths(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """float [N]: metres of a -> b within `wall_margin` of a wall (overlapping grown walls count
        twice where they overlap: a planning cost, not a measurement)."""
        return self.obstacles.collision_lengths(a, b)

    def is_free(self, position: np.ndarray) -> bool:
        return bool(self.obstacles.clearance(np.asarray(position, np.float64)[None])[0] > 0.0)

    # --- tasks ---------------------------------------------------------------------------------
    def sample_tasks(self, n: int, split: str = "train", seed: int | None = None):
        """(starts, goals) float32 [n, 2], deterministic for (split, seed): both clear of the grown
        walls by `success_radius`, at least `min_task_distance` apart, connected."""
        seed = self.config["task_seed"] if seed is None else seed
        return sample_task_pairs(
            self.agent_geometry,
            self.obstacles,
            n,
            split_rng(split, seed),
            margin=self.success_radius,
            min_separation=float(self.config["min_task_distance"]),
        )

    def tasks(self, split: str) -> tuple[np.ndarray, np.ndarray]:
        """The fixed task sets: `train`, `validation` and `test` (num_<split>_tasks each), disjoint."""
        check_task_set(split)
        if not self._fixed:
            sizes = {name: self.config[f"num_{name}_tasks"] for name in TASK_SETS}
            self._fixed = draw_task_sets(self.sample_tasks, sizes, self.config["test_set"])
        starts, goals = self._fixed[split]
        return starts.copy(), goals.copy()

    def _position(self, value: Any, key: str, must_be_free: bool) -> np.ndarray:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
        if arr.shape != (2,) or not np.isfinite(arr).all():
            raise ValueError(f"{key} must be 2 finite numbers (x, y in metres), got {value!r}")
        if not self.goal_space.contains(arr.astype(np.float32)):
            low, high = self.goal_space.low.tolist(), self.goal_space.high.tolist()
            raise ValueError(f"{key} {arr.tolist()} lies outside the {self.map_name} maze ({low} .. {high})")
        if must_be_free and not self.is_free(arr):
            raise ValueError(
                f"{key} {arr.tolist()} lies in a wall of the {self.map_name} maze or within "
                f"wall_margin={self.config['wall_margin']:g} m of one"
            )
        return arr

    def set_render_path(self, points: Any) -> None:
        self._render_path = None if points is None else np.asarray(points, np.float64).reshape(-1, 2)

    # --- gymnasium API -------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"start", "goal"}
        if unknown:
            raise ValueError(f"unknown reset option {sorted(unknown)[0]!r}; valid: start, goal")
        if set(options) == {"goal"} and self._started:
            # A new sub-goal, same motion (a flipped Ant is stood up where it lies).
            self._goal = self._position(options["goal"], "goal", must_be_free=False)
            if self._failed:
                self._place(self._obs[:2].copy())
        else:
            if "start" in options:
                if "goal" not in options:
                    raise ValueError("reset option 'start' needs 'goal' too")
                start = self._position(options["start"], "start", must_be_free=True)
                goal = self._position(options["goal"], "goal", must_be_free=False)
            elif "goal" in options:  # goal only, but nothing to continue yet: from a training start
                start = self._draw_task()[0]
                goal = self._position(options["goal"], "goal", must_be_free=False)
            else:
                start, goal = self._draw_task()
            self._goal = goal
            self._place(start)
        self._steps, self._collisions, self._failed = 0, 0, False
        self._ant.model.site_pos[self._target_site][:2] = self._goal
        return self._observation(), self._info(collision=False)

    def _draw_task(self) -> tuple[np.ndarray, np.ndarray]:
        if self.config["task_split"] == "uniform":
            starts, goals = self.sample_tasks(1, "uniform", seed=int(self.np_random.integers(2**31)))
            return starts[0].astype(np.float64), goals[0].astype(np.float64)
        starts, goals = self.tasks(self.config["task_split"])
        i = int(self.np_random.integers(len(starts)))
        return starts[i].astype(np.float64), goals[i].astype(np.float64)

    def _place(self, xy: np.ndarray) -> None:
        """The Ant standing still at (x, y) in its initial pose."""
        self._ant.init_qpos[:2] = xy
        self._obs, _ = self._ant.reset()
        self._started = True

    def step(self, action: Any):
        action = np.clip(np.asarray(action, np.float64), -1.0, 1.0)
        self._obs, _, _, _, _ = self._ant.step(action)
        self._steps += 1
        collision = self._touches_wall()
        flipped = self._ant.data.xmat[self._torso][8] < 0.0  # torso z axis . world z
        self._failed |= bool(flipped)
        collision |= bool(flipped)
        self._collisions += int(collision)
        obs = self._observation()
        info = self._info(collision=collision)
        reward = self.compute_reward(obs["achieved_goal"], obs["desired_goal"])
        terminated = self.compute_terminated(obs["achieved_goal"], obs["desired_goal"])
        truncated = not terminated and (self._failed or self._steps >= self.max_episode_steps)
        return obs, reward, terminated, truncated, info

    def _touches_wall(self) -> bool:
        data = self._ant.data
        if data.ncon == 0:
            return False
        g1, g2 = data.contact.geom1, data.contact.geom2
        pair = (self._wall_geom[g1] & self._ant_geom[g2]) | (self._wall_geom[g2] & self._ant_geom[g1])
        return bool(pair.any())

    def _observation(self) -> dict[str, np.ndarray]:
        obs = self._obs.astype(np.float32)
        return {
            "observation": obs,
            "achieved_goal": obs[:2].copy(),
            "desired_goal": self._goal.astype(np.float32),
        }

    def _info(self, collision: bool) -> dict[str, Any]:
        distance = float(self.goal_distance(self._obs[:2], self._goal))
        return {
            "collision": bool(collision),
            "failed": self._failed,
            "success": bool(distance <= self.success_radius and self._collisions == 0),
            "num_collisions": self._collisions,
            "distance": distance,
        }

    # --- rendering -----------------------------------------------------------------------------
    def render(self):
        if self.render_mode != "rgb_array":
            return None
        import mujoco

        size = int(self.config["render_size"])
        model, data = self._ant.model, self._ant.data
        if self._renderer is None:
            self._renderer = mujoco.Renderer(model, size, size)
        camera = mujoco.MjvCamera()
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = (0.0, 0.0, 0.0)
        camera.distance = 1.2 * float(np.max(self.goal_space.high - self.goal_space.low))
        camera.elevation, camera.azimuth = -90.0, 90.0  # from straight above, +y up in the image
        self._renderer.update_scene(data, camera)
        markers = [] if self._render_path is None else list(self._render_path)
        for p in markers:
            self._add_marker(p, radius=0.25, rgba=(1.0, 0.6, 0.0, 1.0))
        return self._renderer.render().copy()

    def _add_marker(self, xy: np.ndarray, radius: float, rgba: tuple[float, ...]) -> None:
        import mujoco

        scene = self._renderer.scene
        if scene.ngeom >= scene.maxgeom:
            return
        mujoco.mjv_initGeom(
            scene.geoms[scene.ngeom],
            mujoco.mjtGeom.mjGEOM_SPHERE,
            np.array([radius, 0.0, 0.0]),
            np.array([xy[0], xy[1], WALL_TOP + radius]),  # above the walls: seen from the top
            np.eye(3).reshape(-1),
            np.asarray(rgba, np.float32),
        )
        scene.ngeom += 1

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self._maze_env.close()


def make_ant_maze(**env_config: Any) -> GoalAntMazeEnv:
    return GoalAntMazeEnv(env_config)
