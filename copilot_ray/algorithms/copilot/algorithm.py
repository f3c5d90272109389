"""CO-PILOT (Algorithm 3 of the paper) as an RLlib Algorithm on the new API stack: `CoPilotConfig` and
`CoPilot`, on top of the goal-conditioned SAC agent (`GoalSACConfig` / `GoalSAC`, which CO-PILOT's
agent is), as RLlib keeps `SACConfig` and `SAC` together.

    config = (
        CoPilotConfig()
        .environment("maze-point", env_config={"layout": "four-rooms"})
        .copilot(tree_depth=5, repetitions=5, alpha_schedule="paper_per_task")   # or preset="paper_literal"
    )
    algo = config.build_algo()

Every CO-PILOT setting (name, default, rule, doc) is declared once in `settings.py` (the agent's in
`copilot_ray/algorithms/sac/settings.py`). What CO-PILOT adds to the agent's iteration (`GoalSAC.training_step`):

    (first call only) planner_warm_start planner phases on the Euclidean + collision cost, no env steps
    tasks <- task_batch_size (s0, g) pairs from the train set (the planner's batch: planner_task_batch_size)
    for repetition in 1..b:
        planner phase   top-down construction (Alg. 1): update pi_p on J^k, sample layer k, k = 1..K  (_trees)
        agent phase     bottom-up traversal (Alg. 2) on the env runners, SAC updates in between     (GoalSAC)
        cost model      D_tau += (start, end, steps) of every sub-task; refit tau_hat          (_after_traversal)
        alpha           the schedule advances one episode                                      (_after_traversal)
    every evaluation: success on validation and test tasks (planned and direct), paths, trees

With `eval_every_env_steps`, an iteration ends at the repetition that passes an evaluation point and the
next one takes up the same batch, so CO-PILOT is evaluated on the cadence of the short-iteration baselines.

Besides the paper's metrics, `copilot/diag/...` says why a run does or does not learn (diagnostics.py).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from ray.rllib.utils.annotations import override

from copilot_ray import keys
from copilot_ray.algorithms.copilot.diagnostics import plan_diagnostics, tau_hat_profile
from copilot_ray.algorithms.copilot.health import check_finite, fill_nan, injected_fault
from copilot_ray.algorithms.copilot.settings import (
    PRESETS,
    SETTINGS,
    alpha_schedule_from,
    combination_problems,
)
from copilot_ray.algorithms.sac.algorithm import GoalSAC, GoalSACConfig
from copilot_ray.planning import (
    AlphaClock,
    AlphaSchedule,
    SegmentCost,
    SubgoalPlanner,
    TimeCostModel,
    construct_trees,
)
from copilot_ray.planning.path_metrics import CountedChecks, RRTReference, rrt_reference
from copilot_ray.settings import Setting, keyword_arguments

_STATE_KEY = "copilot"
# Tasks per planner phase of the warm start: the paper's task mini-batch for the maze.
WARM_START_TASKS = 30
# Segment lengths at which tau_hat is profiled at every evaluation (the report's diagnostics page).
TAU_PROFILE_LENGTHS = np.array([0.0125, 0.025, 0.05, 0.1, 0.2, 0.4])


def _obstacle_arrays(env) -> dict[str, np.ndarray]:
    """The env's obstacle boxes and region for the tree artifact (empty for an env without `obstacles`)."""
    obstacles = getattr(env, "obstacles", None)
    if obstacles is None:
        return {}
    return {
        "walls_lo": obstacles.lo,
        "walls_hi": obstacles.hi,
        "region": np.stack([obstacles.region_lo, obstacles.region_hi]),
    }


class CoPilotConfig(GoalSACConfig):
    """The goal-conditioned agent's config plus CO-PILOT's settings, set with `.copilot(...)`
    (`settings.SETTINGS` lists them with their rules; the agent's are accepted there too)."""

    SETTINGS: ClassVar[Mapping[str, Setting]] = SETTINGS
    NESTED: ClassVar[tuple[str, ...]] = ("planner", "cost_model")

    @override(GoalSACConfig)
    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or CoPilot)
        # The schedule is kept as its full mapping (a preset name is only a way to write one).
        self.alpha_schedule: dict[str, Any] = AlphaSchedule.from_dict(self.alpha_schedule).to_dict()

    @classmethod
    def _is_value(cls, s: Setting) -> bool:
        # `alpha_schedule.<field>` (sweep specs) are fields of the one `alpha_schedule` value.
        return s.target != "alpha_schedule" or s.key == "alpha_schedule"

    def _set_values(self, values: Mapping[str, Any]) -> None:
        """`preset` first, every other value over it; the alpha schedule from its dotted fields."""
        self._refuse_unknown(values, "from_settings")
        rest = {k: v for k, v in values.items() if self._is_value(SETTINGS[k]) and k != "preset"}
        schedule = alpha_schedule_from(values)
        if schedule is not None:
            rest["alpha_schedule"] = schedule
        self.copilot(**({"preset": values["preset"]} if "preset" in values else {}))
        training = {k: v for k, v in rest.items() if SETTINGS[k].target == "training"}
        nested = {k: v for k, v in rest.items() if SETTINGS[k].target in self.NESTED}
        self._apply(nested)
        self.copilot(**{k: v for k, v in rest.items() if k not in training and k not in nested})
        if training:
            self.training(**training)

    @keyword_arguments(SETTINGS, ("copilot", "agent", "alpha_schedule"), NESTED)
    def copilot(self, **settings: Any) -> CoPilotConfig:
        """Sets CO-PILOT's settings (and the agent's) by name (`settings.SETTINGS` lists them).

        preset: a key of `settings.PRESETS` (e.g. "paper_literal"), applied first; the other arguments of
        the same call override it. planner / cost_model: dicts that update the current ones key by key.
        alpha_schedule: a preset name ("paper_per_task": 0.9 -> 0.1 over every task's b episodes;
        "paper_warm_start": 1 -> 0 over the first two episodes), a dict (see AlphaSchedule), or an
        AlphaSchedule. Values are checked by `validate()`; unknown names are refused here.
        """
        known = {k for k, s in SETTINGS.items() if "." not in k and s.target != "training"} | set(self.NESTED)
        unknown = sorted(set(settings) - known)
        if unknown:
            import difflib

            close = difflib.get_close_matches(unknown[0], sorted(known), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            training = [k for k in unknown if k in SETTINGS and SETTINGS[k].target == "training"]
            where = f"; {training[0]} is SAC's: set it with .training(...)" if training else ""
            raise ValueError(f"CoPilotConfig.copilot: unknown setting {unknown[0]!r}{hint}{where}")
        if "preset" in settings:
            name = settings.pop("preset")
            if name not in PRESETS:
                raise ValueError(f"CoPilotConfig: preset={name!r} is invalid: use one of {sorted(PRESETS)}")
            self.preset = name
            self._apply_preset(PRESETS[name])
        if "alpha_schedule" in settings:
            schedule = settings["alpha_schedule"]
            if isinstance(schedule, str):
                schedule = AlphaSchedule.preset(schedule)
            if isinstance(schedule, AlphaSchedule):
                schedule = schedule.to_dict()
            # Anything else is kept as given: validate() names it.
            settings["alpha_schedule"] = dict(schedule) if isinstance(schedule, dict) else schedule
        for name in self.NESTED:
            if name in settings:
                settings[name] = {**getattr(self, name), **settings[name]}
        for key, value in settings.items():
            setattr(self, key, value)
        return self

    def _apply_preset(self, values: dict[str, Any]) -> None:
        for key, value in values.items():
            if key in self.NESTED:
                setattr(self, key, {**getattr(self, key), **value})
            elif SETTINGS[key].target == "training":
                self.training(**{key: copy.deepcopy(value)})
            else:
                setattr(self, key, copy.deepcopy(value))

    def _check_settings(self) -> None:
        try:
            AlphaSchedule.from_dict(self.alpha_schedule)
        except (ValueError, TypeError) as err:
            raise ValueError(
                f"CoPilotConfig: alpha_schedule={self.alpha_schedule!r} is invalid: {err}"
            ) from err
        super()._check_settings()

    def _combination_problems(self, values: Mapping[str, Any]):
        return combination_problems({k: v for k, v in values.items() if k != "alpha_schedule"})

    def collision_penalty_value(self) -> float:
        """`collision_penalty`, or its default for `collision_cost` (10 per segment, 100 per length)."""
        if self.collision_penalty is not None:
            return float(self.collision_penalty)
        return 100.0 if self.collision_cost == "length" else 10.0


class CoPilot(GoalSAC):
    """CO-PILOT: a sub-goal planner pi_p and the goal-conditioned SAC agent trained together.

    `GoalSAC` (the env runners sampling `TraversalEnv`, where one episode is one sub-task; the fast
    goal-conditioned SAC learner; evaluation; checkpoints) with Algorithm 3 of the paper in its hooks:
    the planner phase plans the trees the agent traverses (`_trees`), and the finished sub-tasks feed the
    time-cost model and advance the alpha schedule (`_after_traversal`). The driver holds and
    checkpoints the planner, the time-cost model tau_hat and its dataset D_tau, and the alpha clock.
    Configure it with `CoPilotConfig` (`.copilot(...)`).
    """

    @classmethod
    @override(GoalSAC)
    def get_default_config(cls):
        """A fresh `CoPilotConfig`."""
        return CoPilotConfig()

    # ----------------------------------------------------------------------------------- setup
    @override(GoalSAC)
    def setup(self, config) -> None:
        """The agent's setup, then the planner, the cost model (D_tau seeded) and the alpha clock."""
        super().setup(config)
        cfg = self.config
        env = self.goal_env.unwrapped
        if cfg.collision_cost == "length" and not hasattr(env, "collision_lengths"):
            raise ValueError(
                f"CoPilotConfig: collision_cost='length' is invalid for env {cfg.goal_env!r}: it has no "
                "collision_lengths(a, b) hook; use collision_cost='indicator'"
            )
        seed = 0 if cfg.seed is None else int(cfg.seed)
        low, high = env.goal_space.low, env.goal_space.high
        self.planner = SubgoalPlanner.from_settings(
            cfg.planner, env.goal_dim, cfg.tree_depth, low, high, seed, geometry=env.agent_geometry
        )
        c = cfg.cost_model
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
            self.cost_model.init_euclidean(c["init_euclidean"], low, high, self._rng, env.goal_distance)
            self.cost_model.fit(c["fit_steps"] * 4, c["batch_size"], self._rng)
        self.alpha_clock = AlphaClock(AlphaSchedule.from_dict(cfg.alpha_schedule), cfg.repetitions)
        self._planner_phases = 0  # for the planner's std annealing; checkpointed
        # Every segment the planner's cost asks about: the "collision checks" of Fig. 4c; checkpointed.
        self._planner_checks = CountedChecks(env.segments_collide)
        self._rrt_cache: RRTReference | None = None  # computed at the first evaluation that needs it
        self._warm_started = cfg.planner_warm_start == 0
        directions = self._rng.standard_normal(self.test_starts.shape)
        self._tau_probe = (self.test_starts, directions / np.linalg.norm(directions, axis=1, keepdims=True))

    # --------------------------------------------------------------------------- the iteration
    def _before_iteration(self) -> None:
        """A fault drill's NaN (None in real runs), the learned weights' check, the planner's warm start."""
        broken = injected_fault(self.iteration + 1, self.config.seed)
        if broken is not None:
            fill_nan(self._learned_parts().get(broken, ()))
        check_finite(self._learned_parts(), self.iteration + 1, "at the start of the iteration")
        if not self._warm_started:
            self._warm_start_planner()

    def _draw_tasks(self) -> np.ndarray:
        """The planner's PPO batch of `planner_task_batch_size` distinct training tasks; the agent
        traverses the first `task_batch_size` of them."""
        cfg = self.config
        n_tasks = min(cfg.task_batch_size, len(self.train_starts))
        n_plan = min(max(cfg.planner_task_batch_size, n_tasks), len(self.train_starts))
        return self._rng.choice(len(self.train_starts), size=n_plan, replace=False)

    def _trees(self, idx: np.ndarray, stats, timing) -> np.ndarray:
        """The planner phase of one repetition (see `_plan`), at the alpha of this episode."""
        alpha = self.alpha_clock.value
        stats[keys.ALPHA].append(alpha)
        t0 = time.perf_counter()
        trees = self._plan(self.train_starts[idx], self.train_goals[idx], alpha, stats)
        timing["planner_s"] += time.perf_counter() - t0
        return trees

    def _after_traversal(self, subtasks: dict[str, np.ndarray], stats, timing) -> None:
        """D_tau gets the repetition's sub-tasks, tau_hat is refit, the alpha schedule advances."""
        t0 = time.perf_counter()
        self._add_to_dtau(subtasks)
        cm = self.config.cost_model
        stats[keys.COST_MODEL_LOSS].append(self.cost_model.fit(cm["fit_steps"], cm["batch_size"], self._rng))
        timing["cost_model_s"] += time.perf_counter() - t0
        self.alpha_clock.advance()

    def _after_iteration(self) -> None:
        check_finite(self._learned_parts(), self.iteration + 1, "after its planner and cost-model updates")

    def _log_iteration(self, timing: Mapping[str, float]) -> None:
        self.metrics.log_value(keys.metric_path(keys.DTAU_SIZE), len(self.cost_model.dataset), window=1)
        # The planner and cost-model phases should stay a small share of the iteration.
        total = sum(timing.values())
        self.metrics.log_value(
            keys.metric_path(keys.PLANNING_SHARE),
            (timing["planner_s"] + timing["cost_model_s"]) / max(total, 1e-9),
            window=1,
        )

    def _collision_checks(self) -> int:
        return self._planner_checks.count

    def _learned_parts(self) -> dict[str, list]:
        """The driver-side learned weights that every plan depends on (health.check_finite)."""
        return {
            "cost_model": list(self.cost_model.net.parameters()),
            "planner": list(self.planner.parameters()),
        }

    # ---------------------------------------------------------------------------- planner phase
    def _segment_cost(self, alpha: float) -> SegmentCost:
        env = self.goal_env.unwrapped
        return SegmentCost(
            alpha=alpha,
            time_cost=self.cost_model.predict,
            segments_collide=self._planner_checks,
            distance=env.goal_distance,
            collision_penalty=self.config.collision_penalty_value(),
            collision_cost=self.config.collision_cost,
            collision_lengths=getattr(env, "collision_lengths", None),
        )

    def _planner_phase(self, starts, goals, cost: SegmentCost, mean_tree: bool):
        """One top-down construction with one PPO update per layer (Algorithm 1)."""
        p = self.config.planner
        if p["std_final"] is not None:
            # Linear annealing of the exploration std over the first std_anneal_phases phases.
            frac = min(1.0, self._planner_phases / p["std_anneal_phases"])
            self.planner.set_std(p["std"] + frac * (p["std_final"] - p["std"]))
        self._planner_phases += 1
        return construct_trees(
            self.planner,
            starts,
            goals,
            self.config.tree_depth,
            cost,
            num_samples=p["num_samples"],
            train=True,
            deterministic=mean_tree,
            rng=self._rng,
        )

    def _warm_start_planner(self) -> None:
        """`planner_warm_start` planner phases on the Euclidean + collision cost (alpha = 1): no env
        steps, so the agent's first sub-goals do not run through walls (SGT-PG's planner, trained alone)."""
        t0 = time.perf_counter()
        cost = self._segment_cost(1.0)
        n = min(WARM_START_TASKS, len(self.train_starts))
        phases = self.config.planner_warm_start
        self.heartbeat.say(f"planner warm start: {phases} planner phases on {n} tasks each (no env steps)")
        for phase in range(phases):
            self.heartbeat.beat(lambda phase=phase: f"planner warm start: phase {phase + 1} of {phases}")
            idx = self._rng.choice(len(self.train_starts), size=n, replace=False)
            built = self._planner_phase(self.train_starts[idx], self.train_goals[idx], cost, mean_tree=True)
        self._warm_started = True
        self.metrics.log_value(
            keys.metric_path(keys.PLANNER_PREFIX + "warm_start_s"), time.perf_counter() - t0, window=1
        )
        self.metrics.log_value(
            keys.metric_path(keys.PLANNER_PREFIX + "warm_start_cost"),
            built.stats["cost_layer_" + str(self.config.tree_depth)],
            window=1,
        )

    def _plan(self, starts: np.ndarray, goals: np.ndarray, alpha: float, stats) -> np.ndarray:
        """Top-down construction (Algorithm 1): trees [B, 2^K + 1, goal_dim].

        The diagnostics describe the first task_batch_size trees, the ones the agent traverses."""
        cfg = self.config
        built = self._planner_phase(
            starts, goals, self._segment_cost(alpha), mean_tree=cfg.traversal_tree == "mean"
        )
        stats[keys.PLANNER_STD].append(float(self.planner.std.mean()))
        env = self.goal_env.unwrapped
        diag = plan_diagnostics(
            built.trees[: cfg.task_batch_size],
            cfg.tree_depth,
            point_collides=lambda p: env.segments_collide(p, p),
            distance=env.goal_distance,
            reachable_length=self._reachable_length,
        )
        for key, value in diag.items():
            stats[key].append(value)
        for k in range(cfg.tree_depth + 1):
            stats[keys.PLANNER_COST_LAYER + str(k)].append(built.stats[f"cost_layer_{k}"])
        # How far PPO moved the planner per layer update (a diverging planner shows here first).
        stats[keys.PLANNER_APPROX_KL_MAX].append(
            max(built.stats[f"approx_kl_layer_{k}"] for k in range(1, cfg.tree_depth + 1))
        )
        stats[keys.PLANNER_NONFINITE_SKIPPED].append(built.stats.get("nonfinite_skipped", 0.0))
        stats[keys.PLANNER_ROLLED_BACK].append(built.stats.get("rolled_back", 0.0))
        return built.trees

    def _add_to_dtau(self, subtasks: dict[str, np.ndarray]) -> None:
        """D_tau <- one tuple per sub-task, failed ones included (paper 3.4); see `dtau_tuples`."""
        env = self.goal_env.unwrapped
        starts, ends, steps = dtau_tuples(
            subtasks, self.config.failed_subtask_cost, env.goal_distance, float(env.nominal_step_distance)
        )
        self.cost_model.add_steps(starts, ends, steps)

    def _reachable_length(self, layer: int) -> float:
        """The longest segment a layer-`layer` sub-task can cover (step limit x step + radius)."""
        env = self.goal_env.unwrapped
        steps = self.rules.step_limit_of(layer, self.config.tree_depth)
        return steps * float(env.nominal_step_distance) + float(getattr(env, "success_radius", 0.0))

    # ------------------------------------------------------------------------------- evaluation
    def _evaluation_plan(self, n: int) -> dict[str, Any]:
        """The agent follows the planner's finest path (its mean tree), `step_limit_of(K)` per sub-goal."""
        return {
            "planner": self.planner,
            "step_limit_of": lambda k: self.rules.step_limit_of(k, self.config.tree_depth),
            "planned_total_steps": None,
        }

    def _tree_tasks(self, n: int) -> int:
        return min(self.config.eval_tree_tasks, n)

    def _rrt_reference(self, n: int):
        cfg = self.config
        if cfg.eval_rrt_reference_s > 0 and self._rrt_cache is None:
            seed = 0 if cfg.seed is None else int(cfg.seed)
            self._rrt_cache = rrt_reference(
                cfg.goal_env, cfg.goal_env_config, n, cfg.eval_rrt_reference_s, seed
            )
        return self._rrt_cache

    def _after_test_evaluation(self, result, env_steps: int) -> None:
        if result.trees is not None:
            self._save_tree_artifact(result, env_steps)

    def _save_tree_artifact(self, result, env_steps: int) -> None:
        """Sub-goal trees of fixed test tasks (all layers) and the agent's steps per sub-task."""
        env = self.goal_env.unwrapped
        # tau_hat along straight segments of a few lengths from the test starts (diagnostics page).
        profile = tau_hat_profile(
            self.cost_model.predict,
            env.goal_distance,
            *self._tau_probe,
            TAU_PROFILE_LENGTHS,
            env.goal_space.low,
            env.goal_space.high,
        )
        directory = Path(self.logdir) / keys.TREES_DIR
        directory.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            directory / f"trees_iter{self.iteration + 1:06d}.npz",
            iteration=self.iteration + 1,
            env_steps=env_steps,
            depth=self.config.tree_depth,
            trees=result.trees,
            subtask_steps=result.tree_subtask_steps,
            subtask_reached=result.tree_subtask_reached,
            layout=np.array(str(self.config.goal_env_config.get("layout", ""))),
            # The obstacles the planner sees, so the figure draws any env's trees over its walls.
            **_obstacle_arrays(env),
            tau_hat_length=profile[0],
            tau_hat=profile[1],
        )

    # ------------------------------------------------------------------------------ checkpoints
    def _own_state(self) -> dict[str, Any]:
        """The planner, tau_hat and D_tau, the alpha clock and the planner's counters ("copilot")."""
        return {
            _STATE_KEY: {
                "planner": self.planner.state_dict(),
                "cost_model": self.cost_model.state_dict(),
                "alpha_clock": self.alpha_clock.state_dict(),
                "planner_phases": self._planner_phases,
                "planner_checks": self._planner_checks.count,
                "warm_started": self._warm_started,
            }
        }

    def _set_own_state(self, state: dict[str, Any]) -> None:
        own = state.get(_STATE_KEY)
        if own is None:
            return
        self.planner.load_state_dict(own["planner"])
        self.cost_model.load_state_dict(own["cost_model"])
        self.alpha_clock.load_state_dict(own["alpha_clock"])
        self._planner_phases = int(own.get("planner_phases", 0))
        self._planner_checks.count = int(own.get("planner_checks", 0))
        self._warm_started = bool(own.get("warm_started", True))


def dtau_tuples(subtasks: dict[str, np.ndarray], failed_subtask_cost: str, distance, step_distance: float):
    """(starts, ends, steps) of the D_tau tuples of finished sub-tasks (the `subtask_records` columns).

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
