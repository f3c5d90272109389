"""`GoalStumpTracksEnv` ("walker-stumps"): Box2D's BipedalWalker on parametric stump tracks.

The CO-PILOT paper's third benchmark (its Fig. 3) is the stump-track walker of Portelas et al. 2019
(teachDRL; later TeachMyAgent's "stump tracks"). Neither package installs on current Python, so this
rebuilds it as a *subclass* of Gymnasium's `BipedalWalker` (gymnasium/envs/box2d/bipedal_walker.py):

* Terrain: `_generate_terrain` is overridden to pave the track as the original did: a flat start pad
  (`TERRAIN_STARTPAD` steps), then, alternately, one stump (one `TERRAIN_STEP` wide) and a flat gap of
  `spacing` world units, up to the track's end. A stump's height is `TERRAIN_STEP * max(0.05,
  N(stump_height, 0.1))`: the mean is in terrain steps (14 / 30 world units), the 0.05 floor is the
  original's (Box2D refuses a flat polygon, so "clipped at 0" needs some floor). Ground roughness is 0,
  as in the stump tracks. The stumps come from the track's own seed, not from `np_random`, so a track
  (stump_height, spacing, seed) is the same terrain every time it is built.
* Parameter ranges (TeachMyAgent's stump tracks): stump height mean in [0, 3] terrain steps, spacing in
  [0, 6] world units (a spacing below 0.01 is 0.01, as in the original: the stumps then touch). Values
  outside are refused with a ValueError naming the key and the value.
* Legs: Gymnasium builds the walker inside `reset` from module constants (`LEG_H` and the fixture
  definitions `LEG_FD` / `LOWER_FD` built from it at import). Rather than copying `reset`, this env
  swaps those three module globals for its leg setting's while `BipedalWalker.reset` runs and puts them
  back afterwards (`_leg_geometry`). Nothing else reads them (`step`, `render` and the contact detector
  do not), so the walker keeps its legs after reset. Leg heights: short 17, default 34 (Gymnasium's),
  long 51 pixels / SCALE (teachDRL's short and default walkers; "long" is 1.5 x default, the leg length
  teachDRL gives its big walker). Not thread-safe: envs in one process must be reset one at a time
  (RLlib's env runners are processes; the evaluation below steps its envs in turn).

Goal-conditioned interface (the one every env in `copilot_ray.envs` offers; see maze/env.py):

* goal = the hull's x (world units), a 1-d goal space [0, FAR_END]: the task is always "from the start
  pad (START_X) to the far end (FAR_END, where Gymnasium's walker finishes)"; what varies is the track.
  `observation` = the walker's 24 numbers (hull angle and velocities, joints, leg contacts, lidar) plus
  the hull's x in the goal's units (so goal - position is exact for the agent).
* `step`: terminated = the goal reached (|x - g| <= success_radius, sparse reward `goal_reward`);
  `info["walker_reward"]` is the walker's own Box2D reward (forward progress, torque and head-angle
  penalties, -100 on falling); a fall (the hull touching the ground, or x < 0) is `info["fallen"]`,
  `info["failed"]` and `info["collision"]` and truncates the episode; passing FAR_END without reaching
  the goal truncates it too (`info["end_of_track"]`), as does `max_episode_steps`.
* `reset(options={"start": s, "goal": g})`: a fresh walker standing at x = s, on a newly drawn track
  when s is on the start pad (a new attempt at the task), else on the current track (a restart
  mid-track, e.g. TraversalEnv's after_failure="restart"); `options["track"] = (stump_height, spacing,
  seed)` pins the track. `reset(options={"goal": g})` (`goal_only_reset`) keeps the walker's state and
  the track and only changes the goal; a fallen walker is stood up where it fell. A plain `reset()`
  draws a track from `task_split`'s set, start START_X, goal FAR_END.
* Track sets: `num_eval_distributions` (50) track distributions (stump_height, spacing) drawn uniformly
  from the parameter ranges (seeded by `task_seed`), or the single fixed `track` distribution; "test"
  has `tracks_per_distribution` (10) tracks of each, "validation" as many other tracks of each (for
  tuning), "train" `train_tracks_per_distribution` (20) other tracks of the same distributions,
  "uniform" a fresh distribution and track at every reset. The sets' tracks come from separate seed
  streams (`task_sets.SPLIT_STREAMS`).
* `evaluate_mastery`: the paper's measure. A batched policy walks every evaluation track in lockstep
  for full episodes (up to 2000 steps, a fall or the far end); a distribution is *mastered* when the
  MEAN of its tracks' walker returns exceeds 230 (Portelas et al.'s threshold).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces
from gymnasium.envs.box2d import bipedal_walker as bw
from gymnasium.utils import EzPickle

from copilot_ray.envs.env_config import bad_value, is_integer, is_number, merged_config
from copilot_ray.envs.goal_env import GoalMetric, SparseGoalReward
from copilot_ray.envs.goal_observation import flat_observation
from copilot_ray.envs.task_sets import SPLIT_STREAMS, check_task_set

# --- geometry of Gymnasium's track (world units: pixels / SCALE) -----------------------------------
TERRAIN_STEP = bw.TERRAIN_STEP  # 14 / 30
TRACK_END = bw.TERRAIN_LENGTH * bw.TERRAIN_STEP  # where the terrain stops (93.3)
FAR_END = (bw.TERRAIN_LENGTH - bw.TERRAIN_GRASS) * bw.TERRAIN_STEP  # the walker's finish line (88.7)
START_X = bw.TERRAIN_STEP * bw.TERRAIN_STARTPAD / 2  # where BipedalWalker.reset puts the hull (4.67)
START_PAD_END = bw.TERRAIN_STARTPAD * bw.TERRAIN_STEP  # the first stump's left edge (9.33)
STUMP_HEIGHT_STD = 0.1  # terrain steps
MIN_STUMP_HEIGHT = 0.05  # terrain steps (the original's floor)
MIN_SPACING = 0.01  # world units (the original's floor)
# TeachMyAgent's stump-track parameter space: stump height mean (terrain steps), spacing (world units).
PARAM_RANGES: dict[str, tuple[float, float]] = {"stump_height": (0.0, 3.0), "spacing": (0.0, 6.0)}
MASTERED_RETURN = 230.0  # a track distribution is mastered above this mean walker return

# Hull x per step of a good walker: Gymnasium's heuristic controller walks 0.053 per step (0.079 at
# most); a trained walker covers the track in 800-1000 steps, about 0.1 per step (5 world units / s).
NOMINAL_STEP_DISTANCE = 0.1

# Leg settings -> leg height (world units); width stays Gymnasium's LEG_W.
LEG_HEIGHTS: dict[str, float] = {"short": 17 / bw.SCALE, "default": 34 / bw.SCALE, "long": 51 / bw.SCALE}


def _leg_fixtures(leg_h: float) -> tuple:
    """(LEG_FD, LOWER_FD) as Gymnasium's module builds them, for legs `leg_h` high."""
    upper = bw.fixtureDef(
        shape=bw.polygonShape(box=(bw.LEG_W / 2, leg_h / 2)),
        density=1.0,
        restitution=0.0,
        categoryBits=0x0020,
        maskBits=0x001,
    )
    lower = bw.fixtureDef(
        shape=bw.polygonShape(box=(0.8 * bw.LEG_W / 2, leg_h / 2)),
        density=1.0,
        restitution=0.0,
        categoryBits=0x0020,
        maskBits=0x001,
    )
    return upper, lower


_LEG_GLOBALS = {name: (h, *_leg_fixtures(h)) for name, h in LEG_HEIGHTS.items()}


@contextlib.contextmanager
def _leg_geometry(legs: str) -> Iterator[None]:
    """Gymnasium's leg constants replaced by `legs`' while the block runs (BipedalWalker.reset reads
    them as module globals when it builds the walker)."""
    saved = (bw.LEG_H, bw.LEG_FD, bw.LOWER_FD)
    bw.LEG_H, bw.LEG_FD, bw.LOWER_FD = _LEG_GLOBALS[legs]
    try:
        yield
    finally:
        bw.LEG_H, bw.LEG_FD, bw.LOWER_FD = saved


class Track(NamedTuple):
    """One track: its distribution's parameters and the seed of its stump heights."""

    stump_height: float  # mean stump height, terrain steps, in PARAM_RANGES["stump_height"]
    spacing: float  # flat gap between stumps, world units, in PARAM_RANGES["spacing"]
    seed: int


SPLITS = SPLIT_STREAMS

DEFAULTS: dict[str, Any] = {
    "legs": "default",
    "track": None,  # a fixed track distribution (stump_height, spacing), or None: the evaluation set's
    "max_episode_steps": 2000,
    "success_radius": 0.5,  # world units: about one stump plus its width; ~10 steps of a walker's pace
    "goal_reward": 1.0,
    # The walker's own Box2D reward (forward progress, torque and head-angle penalties, -100 on a fall)
    # times this, reported per step as info["dense_reward"]: the agents add it to their sparse
    # (sub-)goal reward. 0: goal rewards only (the paper's R / 2^k reading of Eq. 6 taken alone).
    "walker_reward_weight": 0.0,
    "task_seed": 0,
    "task_split": "train",
    "num_eval_distributions": 50,
    "tracks_per_distribution": 10,
    "train_tracks_per_distribution": 20,
    "render_mode": None,
}


def check_track_params(stump_height: Any, spacing: Any, key: str = "track") -> tuple[float, float]:
    """(stump_height, spacing) as floats, or a ValueError naming `key` and the value out of range."""
    for name, value in (("stump_height", stump_height), ("spacing", spacing)):
        low, high = PARAM_RANGES[name]
        if not (is_number(value) and low <= value <= high):
            raise ValueError(f"{key} {name} = {value!r}: must be a number in [{low:g}, {high:g}]")
    return float(stump_height), float(spacing)


def _check_config(config: Mapping[str, Any]) -> dict[str, Any]:
    """Merge over DEFAULTS; reject unknown keys and bad values, naming the key and the value."""
    cfg = merged_config("walker-stumps", config, DEFAULTS)

    def bad(key: str, need: str) -> ValueError:
        return bad_value(cfg, key, need)

    if cfg["legs"] not in LEG_HEIGHTS:
        raise bad("legs", f"one of {', '.join(LEG_HEIGHTS)}")
    if cfg["track"] is not None:
        track = cfg["track"]
        if isinstance(track, str | bytes) or not hasattr(track, "__len__") or len(track) != 2:
            raise bad("track", "None or a pair (stump_height, spacing)")
        cfg["track"] = check_track_params(track[0], track[1], key="env_config['track']")
    if not (is_number(cfg["success_radius"]) and 0 < cfg["success_radius"] < FAR_END / 4):
        raise bad("success_radius", f"a number in (0, {FAR_END / 4:.3g}) (world units)")
    if not is_number(cfg["goal_reward"]):
        raise bad("goal_reward", "a finite number")
    if not (is_number(cfg["walker_reward_weight"]) and cfg["walker_reward_weight"] >= 0):
        raise bad("walker_reward_weight", "a number >= 0")
    for key in (
        "max_episode_steps",
        "num_eval_distributions",
        "tracks_per_distribution",
        "train_tracks_per_distribution",
    ):
        if not (is_integer(cfg[key]) and cfg[key] > 0):
            raise bad(key, "a positive integer")
    if not (is_integer(cfg["task_seed"]) and cfg["task_seed"] >= 0):
        raise bad("task_seed", "a non-negative integer")
    if cfg["task_split"] not in SPLITS:
        raise bad("task_split", f"one of {', '.join(SPLITS)}")
    if cfg["render_mode"] not in (None, "rgb_array"):
        raise bad("render_mode", "None or 'rgb_array'")
    return cfg


def evaluation_distributions(num: int, seed: int = 0) -> np.ndarray:
    """float64 [num, 2]: (stump_height, spacing) uniform over PARAM_RANGES, deterministic for seed."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 7919]))
    low = np.array([PARAM_RANGES["stump_height"][0], PARAM_RANGES["spacing"][0]])
    high = np.array([PARAM_RANGES["stump_height"][1], PARAM_RANGES["spacing"][1]])
    return low + (high - low) * rng.random((int(num), 2))


def _track_seed(task_seed: int, split: str, distribution: int, index: int) -> int:
    """A track's seed: distinct streams for every (task_seed, split, distribution, index)."""
    seq = np.random.SeedSequence([int(task_seed), SPLITS[split], int(distribution), int(index)])
    return int(seq.generate_state(1, np.uint32)[0])


@dataclass(frozen=True)
class TrackGeometry:
    """The planner's view of the goal space (what `agent_geometry` is for the maze envs): a segment
    [0, FAR_END] of hull x positions, no angles, nothing to collide with."""

    low: float = 0.0
    high: float = FAR_END
    nominal_step_distance: float = NOMINAL_STEP_DISTANCE
    angle_dims: tuple[int, ...] = ()
    distance_weights: tuple[float, ...] = (1.0,)
    config_dim: int = 1

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([self.low]), np.array([self.high])

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.abs(np.asarray(b, np.float64) - np.asarray(a, np.float64))[..., 0]


class GoalStumpTracksEnv(SparseGoalReward, bw.BipedalWalker):
    """BipedalWalker on a stump track heading for a hull x position (module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": bw.FPS}
    goal_only_reset = True  # reset(options={"goal": g}) keeps the walker's state and the track

    def __init__(self, env_config: Mapping[str, Any] | None = None, **kwargs: Any):
        cfg = _check_config({**dict(env_config or {}), **kwargs})
        super().__init__(render_mode=cfg["render_mode"], hardcore=False)
        EzPickle.__init__(self, dict(cfg))  # rebuild from this env's config, not the base's arguments
        self.config = cfg
        self.legs_setting = cfg["legs"]
        self.leg_height = LEG_HEIGHTS[cfg["legs"]]
        self.success_radius = float(cfg["success_radius"])
        self.goal_reward = float(cfg["goal_reward"])
        self.max_episode_steps = int(cfg["max_episode_steps"])

        self.agent_geometry = TrackGeometry()
        self.goal_dim = 1
        self.goal_space = spaces.Box(np.float32(0.0), np.float32(FAR_END), shape=(1,), dtype=np.float32)
        walker = self.observation_space  # the base's 24-dim Box
        low = np.append(walker.low, -np.inf).astype(np.float32)
        high = np.append(walker.high, np.inf).astype(np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(low, high, dtype=np.float32),
                "achieved_goal": self.goal_space,
                "desired_goal": self.goal_space,
            }
        )
        self.track: Track | None = None
        self.stumps = np.zeros((0, 3))  # [n, 3]: left x, right x, top y (world units)
        self._tracks: dict[str, list[Track]] = {}
        self._goal = FAR_END
        self._state = np.zeros(24, np.float32)
        self._steps = 0
        self._started = False
        self._raw_step = False  # True while BipedalWalker.reset takes its own first step
        self._render_path: np.ndarray | None = None

    # --- planning interface --------------------------------------------------------------------
    @property
    def nominal_step_distance(self) -> float:
        """Hull x per step of a good walker: turns distances into step counts."""
        return NOMINAL_STEP_DISTANCE

    goal_metric = GoalMetric((1.0,))  # goal_distance as data: |x_a - x_b|

    def goal_distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """[N, 1], [N, 1] -> [N] (or [1], [1] -> scalar): |x_a - x_b|."""
        return np.abs(np.asarray(b, np.float64) - np.asarray(a, np.float64))[..., 0]

    def segments_collide(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N], all False: the goal space (hull x) has nothing to collide with."""
        return np.zeros(np.asarray(a).shape[:-1], bool)

    def collision_lengths(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.zeros(np.asarray(a).shape[:-1], np.float64)

    def is_free(self, position: np.ndarray) -> bool:
        """Every x of the goal space is a place a walker can be put (stood on whatever is there)."""
        return bool(self.goal_space.contains(np.asarray(position, np.float32).reshape(1)))

    # --- tracks and tasks ------------------------------------------------------------------------
    def distributions(self) -> np.ndarray:
        """float64 [D, 2] (stump_height, spacing): the fixed `track`, or the evaluation set's."""
        if self.config["track"] is not None:
            return np.array([self.config["track"]], np.float64)
        return evaluation_distributions(self.config["num_eval_distributions"], self.config["task_seed"])

    def tracks(self, split: str) -> list[Track]:
        """The tracks of `split` ("train", "validation" or "test"), distribution by distribution."""
        check_task_set(split)
        if split not in self._tracks:
            per = self.config[
                "train_tracks_per_distribution" if split == "train" else "tracks_per_distribution"
            ]
            seed = self.config["task_seed"]
            self._tracks[split] = [
                Track(float(h), float(s), _track_seed(seed, split, d, i))
                for d, (h, s) in enumerate(self.distributions())
                for i in range(per)
            ]
        return list(self._tracks[split])

    def tasks(self, split: str) -> tuple[np.ndarray, np.ndarray]:
        """(starts, goals) float32 [n, 1], one row per track of `split`: every row is (START_X, FAR_END);
        the variety is the track, which a reset draws (the i-th row is not tied to the i-th track)."""
        n = len(self.tracks(split))
        return np.full((n, 1), START_X, np.float32), np.full((n, 1), FAR_END, np.float32)

    def _draw_track(self) -> Track:
        split = self.config["task_split"]
        if split == "uniform":
            if self.config["track"] is not None:
                h, s = self.config["track"]
            else:
                h, s = evaluation_distributions(1, int(self.np_random.integers(2**31)))[0]
            return Track(float(h), float(s), int(self.np_random.integers(2**31)))
        tracks = self.tracks(split)
        return tracks[int(self.np_random.integers(len(tracks)))]

    def _as_track(self, value: Any) -> Track:
        if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != 3:
            raise ValueError(f"reset option 'track' = {value!r}: must be (stump_height, spacing, seed)")
        h, s = check_track_params(value[0], value[1], key="reset option 'track'")
        if not (is_integer(value[2]) and value[2] >= 0):
            raise ValueError(f"reset option 'track' seed = {value[2]!r}: must be a non-negative integer")
        return Track(h, s, int(value[2]))

    def _x(self, value: Any, key: str) -> float:
        arr = np.asarray(value, np.float64).reshape(-1)
        if arr.shape != (1,) or not np.isfinite(arr).all():
            raise ValueError(f"{key} = {value!r}: must be 1 finite number (hull x, world units)")
        if not self.goal_space.contains(arr.astype(np.float32)):
            raise ValueError(f"{key} = {arr.tolist()}: outside the goal space [0, {FAR_END:.4g}]")
        return float(arr[0])

    def mastery(
        self,
        policy: Policy,
        path: np.ndarray | None = None,
        with_delta: bool = False,
        split: str = "test",
        **counts: Any,
    ) -> MasteryResult:
        """`evaluate_mastery` on this env's config, the agent conditioned as in training: on the far end
        (`path` None: the agent alone), or on the first sub-goal of `path` ([P, 1], the planned
        waypoints along the track) more than `success_radius` ahead of the hull (the plan followed by
        position, since every track shares the one task). `with_delta`: the policy also sees
        goal - achieved (agent_input="state_goal_delta"). `split`: the track set walked ("test" or
        "validation"). `counts`: num_distributions, tracks_per_distribution (default: the env_config's)."""
        ahead = None if path is None else np.sort(np.asarray(path, np.float32).reshape(-1)[1:])

        def observe(obs: dict[str, np.ndarray]) -> np.ndarray:
            achieved = obs["achieved_goal"]
            if ahead is None:
                goal = obs["desired_goal"]
            else:
                index = np.searchsorted(ahead, achieved[:, 0] + self.success_radius, side="right")
                goal = ahead[np.minimum(index, len(ahead) - 1)][:, None]
            return flat_observation(obs["observation"], goal, achieved if with_delta else None)

        return evaluate_mastery(policy, self.config, observe=observe, split=split, **counts)

    def set_render_path(self, points: Any) -> None:
        """Sub-goals [P, 1] drawn as markers on the track by `render()`; None clears."""
        self._render_path = None if points is None else np.asarray(points, np.float64).reshape(-1)

    # --- terrain -----------------------------------------------------------------------------------
    def _generate_terrain(self, hardcore: bool) -> None:
        """The stump track `self.track`: start pad, then one stump and one `spacing` gap in turn."""
        track = self.track
        assert track is not None
        rng = np.random.default_rng(track.seed)
        spacing = max(MIN_SPACING, track.spacing)
        y = bw.TERRAIN_HEIGHT
        self.terrain, stumps = [], []
        xs = [0.0, START_PAD_END]
        x = START_PAD_END
        while x < TRACK_END:
            height = TERRAIN_STEP * max(MIN_STUMP_HEIGHT, rng.normal(track.stump_height, STUMP_HEIGHT_STD))
            poly = [(x, y), (x + TERRAIN_STEP, y), (x + TERRAIN_STEP, y + height), (x, y + height)]
            self.fd_polygon.shape.vertices = poly
            body = self.world.CreateStaticBody(fixtures=self.fd_polygon)
            body.color1, body.color2 = (255, 255, 255), (153, 153, 153)
            self.terrain.append(body)
            stumps.append((x, x + TERRAIN_STEP, y + height))
            x += TERRAIN_STEP + spacing
            xs += [x - spacing, x]
        self.stumps = np.array(stumps, np.float64).reshape(-1, 3)
        self.terrain_x, self.terrain_y = xs, [y] * len(xs)
        # The ground: flat edges between the terrain points, as Gymnasium draws and collides them.
        self.terrain_poly = []
        for i in range(len(xs) - 1):
            if xs[i + 1] <= xs[i]:
                continue
            poly = [(xs[i], y), (xs[i + 1], y)]
            self.fd_edge.shape.vertices = poly
            body = self.world.CreateStaticBody(fixtures=self.fd_edge)
            body.color1 = body.color2 = (76, 255 if i % 2 == 0 else 204, 76)
            self.terrain.append(body)
            self.terrain_poly.append((poly + [(poly[1][0], 0), (poly[0][0], 0)], (102, 153, 76)))
        self.terrain.reverse()

    def stump_heights(self) -> np.ndarray:
        """[n] heights of the current track's stumps in terrain steps (the distribution's units)."""
        return (self.stumps[:, 2] - bw.TERRAIN_HEIGHT) / TERRAIN_STEP

    # --- gymnasium API -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        options = dict(options or {})
        unknown = set(options) - {"start", "goal", "track"}
        if unknown:
            raise ValueError(f"unknown reset option {sorted(unknown)[0]!r}; valid: start, goal, track")
        if "start" in options and "goal" not in options:
            raise ValueError("reset option 'start' needs 'goal' too")
        goal = self._x(options["goal"], "reset option 'goal'") if "goal" in options else FAR_END
        if set(options) == {"goal"} and self._started:
            if seed is not None:
                super(bw.BipedalWalker, self).reset(seed=seed)  # gym.Env's: seeds np_random only
            self._goal = goal
            if self.game_over or self.hull.position.x < 0:  # fallen: stood up where it fell
                self._fresh_walker(float(np.clip(self.hull.position.x, START_X, FAR_END)), seed=None)
        else:
            start = self._x(options["start"], "reset option 'start'") if "start" in options else START_X
            if "track" in options:
                self.track = self._as_track(options["track"])
            elif self.track is None or start < START_PAD_END:
                if seed is not None:  # seed np_random before the track is drawn from it
                    super(bw.BipedalWalker, self).reset(seed=seed)
                    seed = None
                self.track = self._draw_track()
            self._goal = goal
            self._fresh_walker(start, seed)
        self._steps = 0
        return self._observation(), self._info(fallen=False, end_of_track=False, walker_reward=0.0)

    def _fresh_walker(self, x: float, seed: int | None) -> None:
        """BipedalWalker.reset on `self.track` with this env's legs, then the walker moved to stand at x."""
        self._raw_step = True
        try:
            with _leg_geometry(self.legs_setting):
                state, _ = super().reset(seed=seed)
            if abs(x - START_X) > 1e-4:
                self._move_walker(x - START_X, self._lift_at(x))
                self.prev_shaping = None  # no progress reward for the move
                state = super().step(np.zeros(4))[0]  # fresh lidar and joint readings at x
        finally:
            self._raw_step = False
        self._state = np.asarray(state, np.float32)
        self._started = True

    def _lift_at(self, x: float) -> float:
        """How far to raise a walker put at hull x so that neither feet nor hull start inside a stump."""
        if not len(self.stumps):
            return 0.0

        def top(lo: float, hi: float) -> float:
            s = self.stumps
            over = (s[:, 0] < hi) & (s[:, 1] > lo)
            return float(s[over, 2].max()) if over.any() else bw.TERRAIN_HEIGHT

        feet_bottom = bw.TERRAIN_HEIGHT - bw.LEG_DOWN  # as BipedalWalker.reset places them
        hull_bottom = bw.TERRAIN_HEIGHT + 2 * self.leg_height + bw.LEG_DOWN
        feet = top(x - 0.4, x + 0.4) - feet_bottom + 0.05
        hull = top(x - 31 / bw.SCALE, x + 35 / bw.SCALE) - hull_bottom + 0.05
        return max(0.0, feet, hull)

    def _move_walker(self, dx: float, dy: float) -> None:
        for body in [self.hull, *self.legs]:
            body.position = (body.position.x + dx, body.position.y + dy)
            body.awake = True

    def step(self, action: Any):
        if self._raw_step:  # BipedalWalker.reset's own first step
            return super().step(action)
        action = np.clip(np.asarray(action, np.float64).reshape(4), -1.0, 1.0)
        state, walker_reward, _, _, _ = super().step(action)
        self._state = np.asarray(state, np.float32)
        self._steps += 1
        x = float(self.hull.position.x)
        fallen = bool(self.game_over or x < 0)
        end_of_track = x > FAR_END
        obs = self._observation()
        info = self._info(fallen=fallen, end_of_track=end_of_track, walker_reward=float(walker_reward))
        reward = self.compute_reward(obs["achieved_goal"], obs["desired_goal"])
        terminated = self.compute_terminated(obs["achieved_goal"], obs["desired_goal"])
        truncated = not terminated and (fallen or end_of_track or self._steps >= self.max_episode_steps)
        return obs, reward, terminated, bool(truncated), info

    def _observation(self) -> dict[str, np.ndarray]:
        x = np.float32(self.hull.position.x)
        return {
            "observation": np.append(self._state, x).astype(np.float32),
            "achieved_goal": np.array([x], np.float32),
            "desired_goal": np.array([self._goal], np.float32),
        }

    def _info(self, fallen: bool, end_of_track: bool, walker_reward: float) -> dict[str, Any]:
        distance = abs(float(self.hull.position.x) - self._goal)
        return {
            "walker_reward": walker_reward,
            "dense_reward": self.config["walker_reward_weight"] * walker_reward,
            "fallen": fallen,
            "failed": fallen,  # what evaluation.py and TraversalEnv read as "cannot go on"
            "collision": fallen,
            "end_of_track": end_of_track,
            "success": bool(distance <= self.success_radius and not fallen),
            "distance": distance,
        }

    # --- rendering ---------------------------------------------------------------------------------
    def render(self):
        if self.render_mode != "rgb_array" or self.hull is None:
            return None
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # offscreen: no display needed
        frame = super().render()
        ground = frame.shape[0] - int(bw.TERRAIN_HEIGHT * bw.SCALE)  # image row of the ground
        left = max(0.0, self.scroll)
        marks = [] if self._render_path is None else [(x, (255, 140, 0)) for x in self._render_path]
        for x, color in [*marks, (self._goal, (220, 0, 0))]:
            col = int(round((x - left) * bw.SCALE))
            if 0 <= col < frame.shape[1]:
                frame[max(0, ground - 150) : ground - 90, max(0, col - 2) : col + 3] = color
        return frame


def make_walker_stumps(**env_config: Any) -> GoalStumpTracksEnv:
    return GoalStumpTracksEnv(env_config)


def make_walker_stumps_short(**env_config: Any) -> GoalStumpTracksEnv:
    """The short-legged walker as an env id of its own (a sweep's `env.id` list is a grid axis)."""
    return GoalStumpTracksEnv({"legs": "short", **env_config})


def make_walker_stumps_long(**env_config: Any) -> GoalStumpTracksEnv:
    return GoalStumpTracksEnv({"legs": "long", **env_config})


# --- the paper's evaluation: mastered track distributions ------------------------------------------
Policy = Callable[[np.ndarray], np.ndarray]


@dataclass
class MasteryResult:
    distributions: np.ndarray  # [D, 2] (stump_height, spacing)
    returns: np.ndarray  # [D, T] walker return of each track
    fallen: np.ndarray  # [D, T] the episode ended in a fall
    steps: np.ndarray  # [D, T] episode lengths
    mastered: np.ndarray  # [D] bool: mean return of the distribution's tracks > threshold

    @property
    def mastered_fraction(self) -> float:
        return float(self.mastered.mean())


def _goal_observation(obs: dict[str, np.ndarray]) -> np.ndarray:
    """What a goal-conditioned agent sees (agent_input="state_goal"): concat(observation, goal)."""
    return flat_observation(obs["observation"], obs["desired_goal"])


def evaluate_mastery(
    policy: Policy,
    env_config: Mapping[str, Any] | None = None,
    *,
    num_distributions: int | None = None,
    tracks_per_distribution: int | None = None,
    max_episode_steps: int = 2000,
    threshold: float = MASTERED_RETURN,
    observe: Callable[[dict[str, np.ndarray]], np.ndarray] = _goal_observation,
    batch_size: int = 100,
    split: str = "test",
) -> MasteryResult:
    """Which evaluation track distributions `policy` masters, by the walker's own reward.

    Every track of `split` ("test", or "validation" for tuning) (the first `num_distributions` distributions of the env's evaluation set, the
    first `tracks_per_distribution` tracks of each; default: the env_config's counts) is walked for a
    full episode: until a fall, the far end or `max_episode_steps`, the goal being the far end (the goal
    reward and goal termination are ignored). `batch_size` envs run in lockstep, one batched
    `policy(observe(obs))` call per step: `observe` defaults to concat(observation, goal) (what CO-PILOT's
    agent sees); pass `lambda o: o["observation"]` for a policy without goals. A distribution is mastered
    when the mean return of its tracks exceeds `threshold` (230)."""
    check_task_set(split)
    cfg = {**dict(env_config or {}), "task_split": split, "max_episode_steps": max_episode_steps}
    cfg.pop("render_mode", None)
    probe = GoalStumpTracksEnv(cfg)
    dists = probe.distributions()
    per_dist = probe.config["tracks_per_distribution"]
    n_dist = len(dists) if num_distributions is None else min(int(num_distributions), len(dists))
    n_track = per_dist if tracks_per_distribution is None else min(int(tracks_per_distribution), per_dist)
    if n_dist < 1 or n_track < 1:
        raise ValueError(f"nothing to evaluate: {n_dist} distributions x {n_track} tracks")
    all_tracks = probe.tracks(split)
    tracks = [all_tracks[d * per_dist + t] for d in range(n_dist) for t in range(n_track)]
    probe.close()
    returns = np.zeros(len(tracks))
    fallen = np.zeros(len(tracks), bool)
    steps = np.zeros(len(tracks), np.int64)
    envs = [GoalStumpTracksEnv(cfg) for _ in range(min(batch_size, len(tracks)))]
    for first in range(0, len(tracks), len(envs)):
        ids = np.arange(first, min(first + len(envs), len(tracks)))
        # Seeded by the track: the walker's initial push is the same in every evaluation.
        obs = [envs[j].reset(seed=tracks[i].seed, options={"track": tracks[i]})[0] for j, i in enumerate(ids)]
        active = np.ones(len(ids), bool)
        for _ in range(max_episode_steps):
            live = np.flatnonzero(active)
            if not len(live):
                break
            batch = {k: np.stack([obs[j][k] for j in live]) for k in obs[0]}
            actions = np.asarray(policy(observe(batch)), np.float64).reshape(len(live), -1)
            for a, j in zip(actions, live, strict=True):
                obs[j], _, _, _, info = envs[j].step(a)
                i = ids[j]
                returns[i] += info["walker_reward"]
                steps[i] += 1
                if info["fallen"] or info["end_of_track"]:
                    fallen[i] = info["fallen"]
                    active[j] = False
    for env in envs:
        env.close()
    shape = (n_dist, n_track)
    returns, fallen, steps = returns.reshape(shape), fallen.reshape(shape), steps.reshape(shape)
    return MasteryResult(dists[:n_dist].copy(), returns, fallen, steps, returns.mean(axis=1) > threshold)


__all__ = [
    "FAR_END",
    "LEG_HEIGHTS",
    "MASTERED_RETURN",
    "PARAM_RANGES",
    "START_X",
    "GoalStumpTracksEnv",
    "MasteryResult",
    "Track",
    "evaluate_mastery",
    "evaluation_distributions",
    "make_walker_stumps",
]
