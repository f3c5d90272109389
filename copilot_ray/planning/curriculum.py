"""A curriculum: the sub-goal trees the goal-conditioned agent traverses instead of its whole tasks, and what
it learns from the traversals. Ray-free: the agent (`algorithms/sac`'s GoalSAC) holds one, or none (SAC, HER,
SoRB traverse [s0, g]). One iteration of the agent, with a curriculum:

    metrics = curriculum.prepare(iteration, rng, heartbeat) before the tasks are drawn (CO-PILOT: warm start)
    idx     = rng.choice(train, curriculum.tasks_to_draw(n))  the planner's batch; the agent traverses n
    repeat b = curriculum.repetitions times:
        trees, metrics = curriculum.trees(starts, goals, n, rng)     the planner phase
        ... the agent traverses the trees (SAC updates in between) ...
        metrics = curriculum.learn(subtasks, rng)          CO-PILOT: D_tau, tau_hat, the alpha clock
    metrics = curriculum.summary()

Every method returns its metrics (full metric names, `copilot_ray.keys`); nothing is passed in to be
filled. `planner` is what evaluation follows (`sample(starts, goals, deterministic=True)`),
`collision_checks` the ground-truth checks spent so far (a privilege), `learned_parts()` the weights the
agent checks stay finite, `state_dict()` what a checkpoint keeps under `state_key`.

`CoPilotCurriculum` is CO-PILOT's (the paper's Algorithms 1 and 3): the planner pi_p, its warm start, the
time-cost model tau_hat and its dataset D_tau, the alpha clock. The RRT* curriculum is in `rrt_trees.py`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from copilot_ray import keys
from copilot_ray.heartbeat import StopRequested

from .alpha_schedule import AlphaClock, AlphaSchedule
from .path_metrics import CountedChecks
from .plan_diagnostics import plan_diagnostics, tau_hat_profile
from .planner import SubgoalPlanner
from .planner_phases import PlannerPhases
from .segment_cost import SegmentCost
from .time_cost import TimeCostModel

# Tasks per planner phase of the warm start: the paper's task mini-batch for the maze.
WARM_START_TASKS = 30
# Segment lengths at which tau_hat is profiled at every evaluation (the report's diagnostics page).
TAU_PROFILE_LENGTHS = np.array([0.0125, 0.025, 0.05, 0.1, 0.2, 0.4])


class Curriculum(Protocol):
    """What the agent asks of a curriculum (see the module docstring)."""

    state_key: str
    depth: int
    repetitions: int
    planner: Any

    def prepare(self, iteration: int, rng: np.random.Generator, heartbeat=None) -> dict[str, float]: ...

    def tasks_to_draw(self, traversed: int) -> int: ...

    def trees(
        self, starts: np.ndarray, goals: np.ndarray, traversed: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, dict[str, float]]: ...

    def learn(self, subtasks: Mapping[str, np.ndarray], rng: np.random.Generator) -> dict[str, float]: ...

    def summary(self) -> dict[str, float]: ...

    @property
    def collision_checks(self) -> int: ...

    def learned_parts(self) -> dict[str, list]: ...

    def tree_extras(self) -> dict[str, np.ndarray]: ...

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: Mapping[str, Any]) -> None: ...


class CoPilotCurriculum:
    """CO-PILOT's planner side (Algorithm 3's planner phase and cost model): see the module docstring.

    settings: CO-PILOT's values, by name: tree_depth, repetitions, task_batch_size, planner_task_batch_size,
    planner_warm_start, planner_frozen, traversal_tree, failed_subtask_cost, collision_cost,
    collision_penalty (its resolved number), alpha_schedule (a mapping), planner and cost_model (their
    fields). reachable_length: layer k -> the longest segment a layer-k sub-task can cover (the traversal's
    step limit in distance, for the plans' diagnostics). `rng` is the run's: drawn from here in the order
    Algorithm 3 draws (the Euclidean D_tau, its first fit, the tau_hat profile's directions)."""

    state_key = "copilot"

    def __init__(
        self,
        env,
        settings: Mapping[str, Any],
        train_tasks: tuple[np.ndarray, np.ndarray],
        probe_starts: np.ndarray,
        reachable_length: Callable[[int], float],
        rng: np.random.Generator,
        seed: int,
    ):
        s = dict(settings)
        if s["collision_cost"] == "length" and not hasattr(env, "collision_lengths"):
            raise ValueError(
                f"CoPilotConfig: collision_cost='length' is invalid for env {type(env).__name__}: it has no "
                "collision_lengths(a, b) hook; use collision_cost='indicator'"
            )
        self.env, self.settings = env, s
        self.depth, self.repetitions = int(s["tree_depth"]), int(s["repetitions"])
        self.train_starts, self.train_goals = train_tasks
        self.reachable_length = reachable_length
        low, high = env.goal_space.low, env.goal_space.high
        self.planner = SubgoalPlanner.from_settings(
            s["planner"], env.goal_dim, self.depth, low, high, seed, geometry=env.agent_geometry
        )
        self.phases = PlannerPhases(self.planner, s["planner"])
        c = s["cost_model"]
        self.cost_model = TimeCostModel(
            env.goal_dim,
            low,
            high,
            hidden=tuple(c["hidden"]),
            lr=c["lr"],
            capacity=c["capacity"],
            step_distance=float(env.nominal_step_distance),
            seed=seed,
        )
        if c["init_euclidean"]:
            # Paper 4.1: D_tau starts with 50,000 tuples whose cost is the Euclidean distance.
            self.cost_model.init_euclidean(c["init_euclidean"], low, high, rng, env.goal_distance)
            self.cost_model.fit(c["fit_steps"] * 4, c["batch_size"], rng)
        self.alpha_clock = AlphaClock(AlphaSchedule.from_dict(s["alpha_schedule"]), self.repetitions)
        # Every segment the planner's cost asks about: the "collision checks" of Fig. 4c; checkpointed.
        self._checks = CountedChecks(env.segments_collide)
        self._warm_started = s["planner_warm_start"] == 0
        directions = rng.standard_normal(probe_starts.shape)
        self._tau_probe = (probe_starts, directions / np.linalg.norm(directions, axis=1, keepdims=True))

    # ------------------------------------------------------------------------------ an iteration
    def prepare(self, iteration: int, rng: np.random.Generator, heartbeat=None) -> dict[str, float]:
        """The warm start, on the first call (of a run: it is checkpointed); `heartbeat`
        (copilot_ray.heartbeat.Heartbeat, optional) says how far it got, and a stop asked for through it
        pauses the warm start between two phases (StopRequested; the next call goes on)."""
        return {} if self._warm_started else self._warm_start(rng, heartbeat)

    def tasks_to_draw(self, traversed: int) -> int:
        """The planner's PPO batch: `planner_task_batch_size` tasks, of which the agent traverses the
        first `traversed` (on the agent's few tasks alone the planner's plans collapsed)."""
        return max(int(self.settings["planner_task_batch_size"]), traversed)

    def trees(
        self, starts: np.ndarray, goals: np.ndarray, traversed: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, dict[str, float]]:
        """One planner phase (Algorithm 1) on the batch at this episode's alpha: the trees of its first
        `traversed` tasks, which the agent traverses. A frozen planner (after its warm start) has no PPO
        batch: it plans those tasks alone."""
        s = self.settings
        if self._frozen():
            starts, goals = starts[:traversed], goals[:traversed]
        alpha = self.alpha_clock.value
        built = self.phases.run(
            starts,
            goals,
            self.depth,
            self._segment_cost(alpha),
            rng,
            train=not self._frozen(),
            deterministic=s["traversal_tree"] == "mean",
        )
        trees = built.trees[:traversed]
        metrics = {keys.ALPHA: alpha, keys.PLANNER_STD: float(self.planner.std.mean())}
        metrics.update(
            plan_diagnostics(
                trees,
                self.depth,
                point_collides=lambda p: self.env.segments_collide(p, p),
                distance=self.env.goal_distance,
                reachable_length=self.reachable_length,
            )
        )
        for k in range(self.depth + 1):
            metrics[keys.PLANNER_COST_LAYER + str(k)] = built.stats[f"cost_layer_{k}"]
        if not self._frozen():  # an update: how far PPO moved the planner (divergence shows here first)
            metrics[keys.PLANNER_APPROX_KL_MAX] = max(
                built.stats[f"approx_kl_layer_{k}"] for k in range(1, self.depth + 1)
            )
            metrics[keys.PLANNER_NONFINITE_SKIPPED] = built.stats.get("nonfinite_skipped", 0.0)
            metrics[keys.PLANNER_ROLLED_BACK] = built.stats.get("rolled_back", 0.0)
        return trees, metrics

    def learn(self, subtasks: Mapping[str, np.ndarray], rng: np.random.Generator) -> dict[str, float]:
        """D_tau gets the repetition's sub-tasks, tau_hat is refit, the alpha schedule advances. Before
        the refit the new tuples score tau_hat (`tau_hat_tracking`): they are not yet fit on."""
        env, c = self.env, self.settings["cost_model"]
        step_distance = float(env.nominal_step_distance)
        starts, ends, steps = dtau_tuples(
            subtasks, self.settings["failed_subtask_cost"], env.goal_distance, step_distance
        )
        metrics = tau_hat_tracking(
            self.cost_model.predict, env.goal_distance, starts, ends, steps, step_distance
        )
        self.cost_model.add_steps(starts, ends, steps)
        metrics[keys.COST_MODEL_LOSS] = self.cost_model.fit(c["fit_steps"], c["batch_size"], rng)
        self.alpha_clock.advance()
        return metrics

    def summary(self) -> dict[str, float]:
        return {keys.DTAU_SIZE: len(self.cost_model.dataset)}

    # ---------------------------------------------------------------------------- what it holds
    @property
    def collision_checks(self) -> int:
        return self._checks.count

    def learned_parts(self) -> dict[str, list]:
        """The learned weights every plan depends on (checked finite every iteration)."""
        return {
            "cost_model": list(self.cost_model.net.parameters()),
            "planner": list(self.planner.parameters()),
        }

    def tree_extras(self) -> dict[str, np.ndarray]:
        """tau_hat along straight segments of a few lengths from the test starts (diagnostics page)."""
        distance, tau = tau_hat_profile(
            self.cost_model.predict,
            self.env.goal_distance,
            *self._tau_probe,
            TAU_PROFILE_LENGTHS,
            self.env.goal_space.low,
            self.env.goal_space.high,
        )
        return {"tau_hat_length": distance, "tau_hat": tau}

    # -------------------------------------------------------------------------------- internals
    def _frozen(self) -> bool:
        """The planner learns no more: `planner_frozen`, once its warm start is done."""
        return bool(self.settings["planner_frozen"]) and self._warm_started

    def _segment_cost(self, alpha: float) -> SegmentCost:
        s = self.settings
        return SegmentCost(
            alpha=alpha,
            time_cost=self.cost_model.predict,
            segments_collide=self._checks,
            distance=self.env.goal_distance,
            collision_penalty=s["collision_penalty"],
            collision_cost=s["collision_cost"],
            collision_lengths=getattr(self.env, "collision_lengths", None),
        )

    def _warm_start(self, rng: np.random.Generator, heartbeat=None) -> dict[str, float]:
        """`planner_warm_start` planner phases on the Euclidean + collision cost (alpha = 1): no env
        steps, so the agent's first sub-goals do not run through walls (SGT-PG's planner, trained alone).

        A stop asked for through `heartbeat` pauses it before the next phase (StopRequested): the phases
        done are `phases.count` (the warm start is the run's first phases), checkpointed with the
        planner, and the next call goes on from there with the run's rng as the pause left it, so a
        paused warm start ends in the planner an uninterrupted one would. `warm_start_s`: the seconds
        of this call (after a pause, the part it ran)."""
        t0 = time.perf_counter()
        cost = self._segment_cost(1.0)
        n = min(WARM_START_TASKS, len(self.train_starts))
        phases, done = self.settings["planner_warm_start"], self.phases.count
        if heartbeat is not None:
            heartbeat.boundary = "the end of this warm-start phase"
            how = f"resuming at phase {done + 1} of {phases}" if done else f"{phases} planner phases"
            heartbeat.say(f"planner warm start: {how} on {n} tasks each (no env steps)")
        for phase in range(done, phases):
            if heartbeat is not None:
                if heartbeat.stop_requested:
                    raise StopRequested(f"planner warm start paused after {phase} of {phases} phases")
                heartbeat.beat(lambda phase=phase: f"planner warm start: phase {phase + 1} of {phases}")
            idx = rng.choice(len(self.train_starts), size=n, replace=False)
            built = self.phases.run(
                self.train_starts[idx], self.train_goals[idx], self.depth, cost, rng, deterministic=True
            )
        self._warm_started = True
        return {
            keys.PLANNER_PREFIX + "warm_start_s": time.perf_counter() - t0,
            keys.PLANNER_WARM_START_COST: built.stats["cost_layer_" + str(self.depth)],
        }

    # ------------------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        """The planner, tau_hat and D_tau, the alpha clock and the planner's counters."""
        return {
            "planner": self.planner.state_dict(),
            "cost_model": self.cost_model.state_dict(),
            "alpha_clock": self.alpha_clock.state_dict(),
            "planner_phases": self.phases.count,
            "planner_checks": self._checks.count,
            "warm_started": self._warm_started,
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.planner.load_state_dict(state["planner"])
        self.cost_model.load_state_dict(state["cost_model"])
        self.alpha_clock.load_state_dict(state["alpha_clock"])
        self.phases.count = int(state.get("planner_phases", 0))
        self._checks.count = int(state.get("planner_checks", 0))
        self._warm_started = bool(state.get("warm_started", True))


def tau_hat_tracking(predict, distance, starts, ends, steps, step_distance: float) -> dict[str, float]:
    """How far tau_hat (`predict`, distance units) is from the env steps the agent took on the tuples
    (start, end, steps), and how far the Euclidean cost is: the diagnostic of whether the agent's time
    costs give the planner something the Euclidean cost does not (both in env steps). Empty for no
    tuple."""
    if len(steps) == 0:
        return {}
    measured = np.asarray(steps, np.float64)
    off = predict(starts, ends) / step_distance - measured
    euclidean = np.asarray(distance(starts, ends), np.float64) / step_distance - measured
    return {
        keys.DIAG_TAU_HAT_ERROR: float(np.mean(np.abs(off))),
        keys.DIAG_TAU_HAT_BIAS: float(np.mean(off)),
        keys.DIAG_EUCLIDEAN_ERROR: float(np.mean(np.abs(euclidean))),
    }


def dtau_tuples(subtasks: Mapping[str, np.ndarray], failed_subtask_cost: str, distance, step_distance: float):
    """(starts, ends, steps) of the D_tau tuples of finished sub-tasks (the `Subtasks` columns).

    "end_state" (the paper): (start, where the agent stopped, steps) for every sub-task.
    "lower_bound": a failed sub-task says what it cost NOT to reach its sub-goal, so its tuple is
    (start, sub-goal, steps + the remaining distance at full speed), a lower bound of the steps the
    sub-task needs. Without it tau_hat never sees a segment longer than the agent ever covered and
    extrapolates long segments as cheap, so the planner learns to lengthen its finest segments.
    """
    starts, ends, steps = subtasks["start"], subtasks["end"], subtasks["steps"].astype(np.float64)
    if failed_subtask_cost == "lower_bound":
        failed = ~subtasks["reached"]
        remaining = distance(subtasks["end"], subtasks["goal"]) / step_distance
        ends = np.where(failed[:, None], subtasks["goal"], ends)
        steps = np.where(failed, steps + remaining, steps)
    return starts, ends, steps
