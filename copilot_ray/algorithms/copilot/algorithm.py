"""CO-PILOT (Algorithm 3 of the paper) as an RLlib Algorithm on the new API stack: `CoPilotConfig` and
`CoPilot`, kept together as RLlib keeps `SACConfig` and `SAC`.

    config = (
        CoPilotConfig()
        .environment("maze-point", env_config={"layout": "four-rooms"})
        .copilot(tree_depth=5, repetitions=5, alpha_schedule="paper_per_task")   # or preset="paper_literal"
    )
    algo = config.build_algo()

Every CO-PILOT setting (name, default, rule, doc) is declared once in `settings.py`. The user names the
goal-conditioned env (`maze-point`); `validate()` swaps in the traversal env that turns each planned
sub-task into one RLlib episode and keeps the goal env's id and config in `goal_env` / `goal_env_config`.

One `training_step` = one task mini-batch, repeated b times:

    (first call only) planner_warm_start planner phases on the Euclidean + collision cost, no env steps
    tasks <- draw task_batch_size (s0, g) pairs from the env's train set
    for repetition in 1..b:
        planner phase   top-down construction (Alg. 1): update pi_p on J^k, sample layer k, k = 1..K
        agent phase     bottom-up traversal (Alg. 2) on the env runners, SAC updates in between
        cost model      D_tau += (start, end, steps) of every sub-task; refit tau_hat
        alpha           the schedule advances one episode
    every eval_interval iterations: success on held-out test tasks (planned and direct)

Besides the paper's metrics, `copilot/diag/...` says why a run does or does not learn (diagnostics.py).
"""

from __future__ import annotations

import copy
import difflib
import logging
import time
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.algorithms.dqn import DQN
from ray.rllib.algorithms.sac import SAC, SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    LEARNER_RESULTS,
    NUM_AGENT_STEPS_SAMPLED_LIFETIME,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
)
from ray.tune.registry import register_env

from copilot_ray import keys
from copilot_ray.algorithms.copilot.agent_updates import make_agent_updater
from copilot_ray.algorithms.copilot.diagnostics import (
    plan_diagnostics,
    tau_hat_profile,
    traversal_diagnostics,
)
from copilot_ray.algorithms.copilot.health import check_finite, fill_nan, injected_fault
from copilot_ray.algorithms.copilot.settings import (
    PRESETS,
    SETTINGS,
    alpha_schedule_from,
    combination_problems,
    defaults,
)
from copilot_ray.algorithms.copilot.traversal_env import TRAVERSAL_ENV_ID, TraversalRules, make_traversal_env
from copilot_ray.algorithms.gc_sac import GradientStepSchedule, use_fast_learner, uses_fast_learner
from copilot_ray.envs import make
from copilot_ray.evaluation import (
    EVAL_SPLITS,
    EvaluationSchedule,
    ModulePolicy,
    SuccessCurve,
    evaluate_copilot,
)
from copilot_ray.planning import (
    AlphaClock,
    AlphaSchedule,
    SegmentCost,
    SubgoalPlanner,
    TimeCostModel,
    construct_trees,
)
from copilot_ray.planning.path_metrics import CountedChecks, RRTReference, path_metrics, rrt_reference
from copilot_ray.registry import RunContext

logger = logging.getLogger(__name__)
RUNNER_RESTORE_TIMEOUT_S = 120  # waiting for a failed env runner to come back when none is left
_STATE_KEY = "copilot"
DETERMINISTIC, SAMPLED = keys.EVAL_ACTIONS
# Tasks per planner phase of the warm start: the paper's task mini-batch for the maze.
WARM_START_TASKS = 30
# Segment lengths at which tau_hat is profiled at every evaluation (the report's diagnostics page).
TAU_PROFILE_LENGTHS = np.array([0.0125, 0.025, 0.05, 0.1, 0.2, 0.4])


# The nested settings dicts of the config (`planner.std` is `config.planner["std"]`).
_NESTED = ("planner", "cost_model")
# What `.copilot(...)` takes: its own settings, the nested dicts and the alpha schedule.
_COPILOT_ARGS = (
    {s.key for s in SETTINGS.values() if s.target == "copilot"} | set(_NESTED) | {"alpha_schedule"}
)


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


class CoPilotConfig(SACConfig):
    """RLlib's `SACConfig` plus CO-PILOT's settings, set with `.copilot(...)` (see `settings.SETTINGS`)."""

    @override(SACConfig)
    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or CoPilot)
        # --- RLlib settings CO-PILOT needs ---
        # One training_step is one task mini-batch x b repetitions: no minimum time or steps.
        self.min_time_s_per_iteration = 0
        self.min_sample_timesteps_per_iteration = 0
        self.num_envs_per_env_runner = 1
        self.num_env_runners = 0
        self.goal_env: str | None = None  # set by validate(): the env the user named
        self.goal_env_config: dict[str, Any] = {}
        # --- every CO-PILOT setting at its declared default ---
        for setting in SETTINGS.values():
            if setting.target == "copilot":
                setattr(self, setting.key, copy.deepcopy(setting.default))
        for name in _NESTED:
            setattr(self, name, defaults(name))
        self.alpha_schedule: dict[str, Any] = AlphaSchedule.from_dict(
            SETTINGS["alpha_schedule"].default
        ).to_dict()
        self.training(**defaults("training"))

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: RunContext) -> CoPilotConfig:
        """A config from flat setting `values` (dotted keys, as in a sweep spec) for one run.

        `preset` is applied first; every other value overrides it. This is how sweeps, `train` and
        benchmarks build CO-PILOT (the registry's `config` entry).
        """
        copilot: dict[str, Any] = {}
        training: dict[str, Any] = {}
        nested: dict[str, dict[str, Any]] = {name: {} for name in _NESTED}
        for key, value in values.items():
            setting = SETTINGS[key]
            if setting.target == "copilot":
                copilot[key] = value
            elif setting.target in nested:
                nested[setting.target][setting.field] = value
            elif setting.target == "training":
                training[key] = value
        copilot.update({name: fields for name, fields in nested.items() if fields})
        schedule = alpha_schedule_from(values)
        if schedule is not None:
            copilot["alpha_schedule"] = schedule
        config = (
            cls()
            .environment(run.env_id, env_config=dict(run.env_config))
            .env_runners(num_env_runners=run.num_env_runners)
            # The run's own process (sampling when there are no runners, and the learner) gets the
            # CPUs not taken by runners; validate() sizes torch's thread pool from it.
            .resources(num_cpus_for_main_process=run.num_cpus_for_main_process)
            .debugging(seed=run.seed)
        )
        if "preset" in copilot:
            config.copilot(preset=copilot.pop("preset"))
        config.copilot(**copilot)
        if training:
            config.training(**training)
        return config

    def copilot(self, **settings: Any) -> CoPilotConfig:
        """Sets CO-PILOT's settings by name (`settings.SETTINGS` lists them with their rules).

        preset: a key of `settings.PRESETS` (e.g. "paper_literal"), applied first; the other arguments of
        the same call override it. planner / cost_model: dicts that update the current ones key by key.
        alpha_schedule: a preset name ("paper_per_task": 0.9 -> 0.1 over every task's b episodes;
        "paper_warm_start": 1 -> 0 over the first two episodes), a dict (see AlphaSchedule), or an
        AlphaSchedule. Values are checked by `validate()`; unknown names are refused here.
        """
        unknown = sorted(set(settings) - _COPILOT_ARGS)
        if unknown:
            close = difflib.get_close_matches(unknown[0], sorted(_COPILOT_ARGS), n=1)
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
        for name in _NESTED:
            if name in settings:
                settings[name] = {**getattr(self, name), **settings[name]}
        for key, value in settings.items():
            setattr(self, key, value)
        return self

    def _apply_preset(self, values: dict[str, Any]) -> None:
        for key, value in values.items():
            if key in _NESTED:
                setattr(self, key, {**getattr(self, key), **value})
            else:
                setattr(self, key, copy.deepcopy(value))

    @override(SACConfig)
    def validate(self) -> None:
        self._validate_copilot()
        # The runners sample the traversal env; remember the goal env the user asked for.
        if self.env != TRAVERSAL_ENV_ID:
            self.goal_env = self.env
            self.goal_env_config = copy.deepcopy(dict(self.env_config or {}))
            self.env = TRAVERSAL_ENV_ID
        self.env_config = {
            "goal_env": self.goal_env,
            "goal_env_config": self.goal_env_config,
            **self.traversal_rules().to_dict(),
        }
        if self.fast_learner and not uses_fast_learner(self):
            # One torch thread per CPU this process holds: more threads than cores make OpenMP spin
            # against other trials and runners (measured 10-20x slower SAC updates on 2 busy cores).
            threads = max(1, int(self.num_cpus_for_main_process or 1))
            use_fast_learner(self, updates_per_env_step=self.utd_ratio(), torch_threads=threads)
        register_traversal_env()
        super().validate()

    def traversal_rules(self) -> TraversalRules:
        """How the agent runs and is rewarded on sub-tasks."""
        return TraversalRules(**{name: getattr(self, name) for name in TraversalRules.__dataclass_fields__})

    def collision_penalty_value(self) -> float:
        """`collision_penalty`, or its default for `collision_cost` (10 per segment, 100 per length)."""
        if self.collision_penalty is not None:
            return float(self.collision_penalty)
        return 100.0 if self.collision_cost == "length" else 10.0

    def utd_ratio(self) -> float:
        """SAC gradient steps per sampled env step.

        `updates_per_env_step` if set; else RLlib's `training_intensity` (timesteps replayed per
        timestep sampled, see SACConfig.training) divided by the train batch size, because one gradient
        step replays one batch; else 1.0 (SB3's `train_freq=1, gradient_steps=1`).
        """
        if self.updates_per_env_step is not None:
            return float(self.updates_per_env_step)
        if self.training_intensity is not None:
            return float(self.training_intensity) / float(self.total_train_batch_size)
        return 1.0

    def setting_values(self) -> dict[str, Any]:
        """Every setting of `settings.SETTINGS` at its current value (dotted keys; schedule fields aside)."""
        values = {}
        for s in SETTINGS.values():
            if s.target in _NESTED:
                values[s.key] = getattr(self, s.target).get(s.field)
            elif s.target != "alpha_schedule" or s.key == "alpha_schedule":
                values[s.key] = getattr(self, s.key)
        return values

    def _validate_copilot(self) -> None:
        def bad(key: str, value: Any, why: str) -> ValueError:
            return ValueError(f"CoPilotConfig: {key}={value!r} is invalid: {why}")

        for name in _NESTED:
            given, known = getattr(self, name), defaults(name)
            unknown = sorted(set(given) - set(known))
            if unknown:
                raise bad(f"{name}.{unknown[0]}", given[unknown[0]], f"known keys are {sorted(known)}")
        try:
            AlphaSchedule.from_dict(self.alpha_schedule)
        except (ValueError, TypeError) as err:
            raise bad("alpha_schedule", self.alpha_schedule, str(err)) from err
        values = self.setting_values()
        for key, value in values.items():
            if key != "alpha_schedule" and (why := SETTINGS[key].problem(value)) is not None:
                raise bad(key, value, why)
        for involved, _, why in combination_problems(values):
            given = " and ".join(f"{key}={values.get(key)!r}" for key in involved)
            raise ValueError(f"CoPilotConfig: {given} do not go together: {why}")
        if self.num_envs_per_env_runner != 1:
            raise bad(
                "num_envs_per_env_runner",
                self.num_envs_per_env_runner,
                "CO-PILOT traverses one sub-task queue per runner; use 1 and scale with num_env_runners",
            )
        if self.env is None:
            raise bad("env", None, 'call .environment("maze-point", env_config={...})')


def register_traversal_env() -> None:
    """Makes the traversal env known to Ray Tune's registry (idempotent, cheap)."""
    register_env(TRAVERSAL_ENV_ID, make_traversal_env)


class CoPilot(SAC):
    """CO-PILOT: a sub-goal planner pi_p and a goal-conditioned SAC agent trained together.

    An RLlib `SAC` whose `training_step` is Algorithm 3 of the paper (see `training_step`). RLlib
    provides the agent's parts: the env runners (sampling `TraversalEnv`, where one episode is one
    sub-task), the RLModule and the learner group (with `fast_learner=True`, the default, the
    goal-conditioned SAC module and learner of `copilot_ray.algorithms.gc_sac`). The driver holds the
    rest and checkpoints it with RLlib's state: the planner (`tree_depth` > 0 only), the time-cost
    model tau_hat and its dataset D_tau, the alpha clock (`alpha_schedule`, `repetitions`), the agent's
    replay buffer, the update-to-data schedule and the random generators. A copy of the goal env
    (`goal_env`) supplies the geometry for the planner's costs and the train / test tasks.
    Configure it with `CoPilotConfig` (`.copilot(...)` for its own knobs).
    """

    @classmethod
    @override(SAC)
    def get_default_config(cls):
        """A fresh `CoPilotConfig`."""
        return CoPilotConfig()

    # ----------------------------------------------------------------------------------- setup
    @override(DQN)
    def setup(self, config) -> None:
        """SAC's setup, then the goal env, planner, cost model (D_tau seeded), alpha clock and tasks."""
        register_traversal_env()
        super().setup(config)
        cfg = self.config
        # A driver-side copy of the goal env: geometry for the planner's cost, tasks, evaluation.
        self.goal_env = make(cfg.goal_env, **cfg.goal_env_config)
        env = self.goal_env.unwrapped
        if cfg.collision_cost == "length" and not hasattr(env, "collision_lengths"):
            raise ValueError(
                f"CoPilotConfig: collision_cost='length' is invalid for env {cfg.goal_env!r}: it has no "
                "collision_lengths(a, b) hook; use collision_cost='indicator'"
            )
        seed = 0 if cfg.seed is None else int(cfg.seed)
        self._rng = np.random.default_rng(seed)
        torch.manual_seed(seed)
        low, high = env.goal_space.low, env.goal_space.high
        # tree_depth 0 is plain goal-conditioned SAC on (s0, g): no planner, one sub-task per task.
        self.planner = (
            None
            if cfg.tree_depth == 0
            else SubgoalPlanner.from_settings(
                cfg.planner, env.goal_dim, cfg.tree_depth, low, high, seed, geometry=env.agent_geometry
            )
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
        self.train_starts, self.train_goals = env.tasks("train")
        # Validation tasks for searchers and probes, test tasks for reports: both at every evaluation.
        self.eval_tasks = {split: env.tasks(split) for split in EVAL_SPLITS}
        self.test_starts, self.test_goals = self.eval_tasks["test"]
        self.eval_schedule = EvaluationSchedule(cfg.eval_interval, cfg.eval_every_env_steps)
        self.success_curves = {split: SuccessCurve() for split in EVAL_SPLITS}
        # Privileges used so far (copilot_ray.privileges): resets to a missed sub-goal and the map
        # queries behind them (after_failure="restart"); collision checks are _planner_checks'.
        self._privileged = {"resets": 0, "map_queries": 0}
        self.rules = cfg.traversal_rules()
        self._planner_phases = 0  # for the planner's std annealing; checkpointed
        # Every segment the planner's cost asks about: the "collision checks" of Fig. 4c; checkpointed.
        self._planner_checks = CountedChecks(env.segments_collide)
        self._rrt_reference: RRTReference | None = None  # computed at the first evaluation that needs it
        self._subtasks_lost = 0  # this iteration's, taken by env runners that died (AGENT_SUBTASKS_LOST)
        self._warm_started = cfg.planner_warm_start == 0 or self.planner is None
        directions = self._rng.standard_normal(self.test_starts.shape)
        self._tau_probe = (self.test_starts, directions / np.linalg.norm(directions, axis=1, keepdims=True))
        self.agent_updater = self._make_agent_updater()
        # Carries the fraction of a gradient step from one call to the next, so a ratio like 0.3 is
        # exact over the run instead of rounded per sampling round.
        self.gradient_steps = GradientStepSchedule(
            cfg.utd_ratio(), learning_starts=cfg.num_steps_sampled_before_learning_starts
        )
        self._artifact_dir: Path | None = None

    def _make_agent_updater(self):
        """What turns sampled episodes into SAC gradient steps (agent_updates.py; HER swaps its buffer in)."""
        return make_agent_updater(self)

    # --------------------------------------------------------------------------- training step
    @override(DQN)
    def training_step(self) -> None:
        """One CO-PILOT iteration: one task mini-batch, `repetitions` (b) episodes on it.

        1. Warm start (first call only; skipped when `planner_warm_start` is 0, when `tree_depth` is
           0, or after restoring a warm-started checkpoint): `planner_warm_start` planner phases
           (step 3a), each on `WARM_START_TASKS` (30) fresh training tasks under alpha = 1 (distance
           + collision cost, no tau_hat), output trees from the policy mean; no env steps. Logs
           `copilot/planner/warm_start_s` and `warm_start_cost`.
        2. Task mini-batch: `max(planner_task_batch_size, task_batch_size)` distinct training tasks
           (s0, g) (at most the whole train set); the agent traverses the first `task_batch_size`,
           the planner trains on all of them. All b repetitions use these tasks.
        3. Each of the b repetitions, with alpha = the `alpha_schedule` value of the current episode
           (and repetition):
           a. Planner phase (`tree_depth` K > 0; with K = 0 the tree is just [s0, g]). With
              `planner["std_final"]` set, the exploration std is first moved linearly from
              `planner["std"]` towards it over `planner["std_anneal_phases"]` phases (warm start
              included). Then for k = 1..K: sample `planner["num_samples"]` trees per task up to layer
              k, cost them by J^k (layers 0..k) with c(a, b) = alpha * dist + (1 - alpha) * tau_hat
              + collision term (`collision_cost`, `collision_penalty`), run one PPO update of pi_p
              over all the planner's tasks (baseline: the mean cost of each task's samples;
              `planner["epochs"]`, `["clip"]`, `["max_grad_norm"]`, `["target_kl"]`, `["max_kl"]`),
              and fill layer k of the output trees (the policy mean, or a sample when
              `traversal_tree="sampled"`).
           b. Agent phase: the agent's trees are dealt round-robin to the env runners
              (`num_env_runners`; 0: the local one), whose `TraversalEnv` queues the bottom-up
              traversal: per task, layers K..0, each layer's 2^k sub-goals left to right, one RLlib
              episode per sub-task (at most `tau_max` steps, times 2^(K-k) with
              `step_limit="scaled"`; `after_failure`, `subtask_reward`, `reward_scale`,
              `agent_collision`, `agent_input`). In rounds, every runner with sub-tasks left samples
              up to `subtasks_per_sample` episodes (explore=True); the episodes go into the replay
              buffer, the learner runs `utd_ratio()` gradient steps
              per new env step (`updates_per_env_step` or `training_intensity`; the fraction carries
              over; none before `num_steps_sampled_before_learning_starts`) on batches of
              `train_batch_size_per_learner`, and the runners get the new weights. Until every
              queue is empty.
           c. Cost model (K > 0): D_tau gets one (start, end, steps) tuple per sub-task, failed ones
              included (`failed_subtask_cost`), then tau_hat is fitted for `cost_model["fit_steps"]`
              steps of `cost_model["batch_size"]`.
           d. The alpha clock advances one episode.
        4. Metrics. Means over the b repetitions: `copilot/alpha`, `copilot/planner/...` (std,
           cost_layer_k, approx_kl_max, nonfinite_skipped, rolled_back), `copilot/diag/...` (plan
           and traversal diagnostics), `copilot/cost_model/loss`, `copilot/agent/...`
           (steps_layer_k, success_layer_k, subtask_success_layer_k). Then `copilot/dtau/size`,
           `copilot/diag/q_mean` (once the learner has run) and `copilot/time/...` (planner_s,
           agent_s, cost_model_s summed over the repetitions; planning_share). RLlib's env-runner and
           learner results are aggregated during the agent phases as usual.
        5. Every `eval_interval` iterations (0: never): the first `eval_num_tasks` test tasks, planned
           (the agent follows the planner's mean tree) and direct (the agent alone with the finest
           plan's step budget), with deterministic and sampled actions -> `copilot/eval/<key>` for
           `eval_action` and `copilot/eval/<action>/<key>`, `copilot/eval/planned_collision_free`,
           `copilot/time/eval_s`; with `eval_tree_tasks` > 0 the sub-goal trees of that many test
           tasks (and tau_hat profiles) are saved to `<logdir>/copilot_trees/trees_iter<N>.npz`.

        Returns None, as RLlib's new API stack expects: everything goes to `self.metrics`, which
        `Algorithm.train()` reduces into the iteration's result dict.
        """
        cfg = self.config
        broken = injected_fault(self.iteration + 1, cfg.seed)  # a fault drill (health.py); None in real runs
        if broken is not None:
            fill_nan(self._learned_parts().get(broken, ()))
        check_finite(self._learned_parts(), self.iteration + 1, "at the start of the iteration")
        self._subtasks_lost = 0
        if not self._warm_started:
            self._warm_start_planner()
        n_tasks = min(cfg.task_batch_size, len(self.train_starts))
        n_plan = min(max(cfg.planner_task_batch_size, n_tasks), len(self.train_starts))
        # The first n_tasks are traversed by the agent; the planner's PPO batch has all n_plan of them.
        idx = self._rng.choice(len(self.train_starts), size=n_plan, replace=False)
        starts, goals = self.train_starts[idx], self.train_goals[idx]
        if self.planner is None:
            idx, starts, goals = idx[:n_tasks], starts[:n_tasks], goals[:n_tasks]
        # Per-repetition figures, averaged over the iteration's b repetitions before logging.
        stats: dict[str, list[float]] = defaultdict(list)
        timing = defaultdict(float)
        for _ in range(cfg.repetitions):
            alpha = self.alpha_clock.value
            stats[keys.ALPHA].append(alpha)

            t0 = time.perf_counter()
            trees = self._plan(starts, goals, alpha, stats)[:n_tasks]
            t1 = time.perf_counter()

            subtasks = self._traverse(trees, idx[:n_tasks])
            t2 = time.perf_counter()
            self._privileged["resets"] += int(subtasks["reset_to_state"].sum())
            self._privileged["map_queries"] += int(subtasks["map_queries"].sum())
            for key, value in self._traversal_diagnostics(subtasks).items():
                stats[key].append(value)

            if self.planner is not None:
                self._add_to_dtau(subtasks)
                stats[keys.COST_MODEL_LOSS].append(
                    self.cost_model.fit(cfg.cost_model["fit_steps"], cfg.cost_model["batch_size"], self._rng)
                )
            t3 = time.perf_counter()
            self.alpha_clock.advance()
            for key, value in _traversal_stats(subtasks, cfg.tree_depth).items():
                stats[key].append(value)
            timing["planner_s"] += t1 - t0
            timing["agent_s"] += t2 - t1
            timing["cost_model_s"] += t3 - t2
        check_finite(self._learned_parts(), self.iteration + 1, "after its planner and cost-model updates")

        for key, values in stats.items():
            self.metrics.log_value(keys.metric_path(key), float(np.mean(values)), window=1)
        self.metrics.log_value(keys.metric_path(keys.AGENT_SUBTASKS_LOST), self._subtasks_lost, window=1)
        for key, count in (
            (keys.PRIVILEGE_COLLISION_CHECKS, self._planner_checks.count),
            (keys.PRIVILEGE_RESETS, self._privileged["resets"]),
            (keys.PRIVILEGE_MAP_QUERIES, self._privileged["map_queries"]),
        ):
            self.metrics.log_value(keys.metric_path(key), count, window=1)
        self.metrics.log_value(keys.metric_path(keys.DTAU_SIZE), len(self.cost_model.dataset), window=1)
        try:
            q_mean = float(self.metrics.peek((LEARNER_RESULTS, DEFAULT_MODULE_ID, "qf_mean")))
        except KeyError:  # no learner update yet
            q_mean = None
        if q_mean is not None:
            self.metrics.log_value(keys.metric_path(keys.DIAG_Q_MEAN), q_mean, window=1)
        total = sum(timing.values())
        for key, value in timing.items():
            self.metrics.log_value(keys.metric_path(keys.TIME_PREFIX + key), value, window=1)
        # The planner and cost-model phases should stay a small share of the iteration.
        self.metrics.log_value(
            keys.metric_path(keys.PLANNING_SHARE),
            (timing["planner_s"] + timing["cost_model_s"]) / max(total, 1e-9),
            window=1,
        )

        env_steps = int(self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))
        if self.eval_schedule.due(self.iteration + 1, env_steps):
            t = time.perf_counter()
            self._evaluate()
            self.metrics.log_value(
                keys.metric_path(keys.TIME_PREFIX + "eval_s"), time.perf_counter() - t, window=1
            )

    def _learned_parts(self) -> dict[str, list]:
        """The driver-side learned weights that every plan depends on (health.check_finite)."""
        parts = {"cost_model": list(self.cost_model.net.parameters())}
        if self.planner is not None:
            parts["planner"] = list(self.planner.parameters())
        return parts

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
        for _ in range(self.config.planner_warm_start):
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
        if self.planner is None:
            return np.stack([starts, goals], axis=1)
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

    def _traversal_diagnostics(self, subtasks: dict[str, np.ndarray]) -> dict[str, float]:
        env = self.goal_env.unwrapped
        return traversal_diagnostics(
            subtasks,
            distance=env.goal_distance,
            success_radius=float(getattr(env, "success_radius", 0.0)),
        )

    # ------------------------------------------------------------------------------ agent phase
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

    def _traverse(self, trees: np.ndarray, task_ids: np.ndarray) -> dict[str, np.ndarray]:
        """Bottom-up traversal of every tree on the env runners, with SAC updates in between.

        Tasks are split over the runners; each round every runner runs its next
        `subtasks_per_sample` sub-tasks, then the learner does `config.utd_ratio()` gradient steps
        per new env step and the runners get the new weights.
        """
        cfg = self.config
        runner_ids = self._runner_ids()
        local = runner_ids == [0]
        shares = {rid: np.arange(i, len(trees), len(runner_ids)) for i, rid in enumerate(runner_ids)}
        plans = {rid: (trees[s], task_ids[s]) for rid, s in shares.items()}
        depth = cfg.tree_depth

        # Every call returns its runner's index: a runner that dies mid-iteration is simply missing from
        # the results (RLlib's restart_failed_env_runners), and its sub-tasks are counted as lost.
        def load(runner):
            tr, ids = plans[runner.worker_index]
            return runner.worker_index, runner.env.unwrapped.call("load_plan", tr, depth, ids)[0]

        loaded = dict(
            self.env_runner_group.foreach_env_runner(
                load, local_env_runner=local, remote_worker_ids=None if local else runner_ids
            )
        )
        per_tree = 2 ** (depth + 1) - 1  # sub-tasks of one tree, all layers
        remaining = {}
        for rid in runner_ids:
            if rid in loaded:
                remaining[rid] = loaded[rid]
            else:
                self._lose_subtasks(rid, len(shares[rid]) * per_tree)
        chunk = cfg.subtasks_per_sample
        records: list[dict[str, np.ndarray]] = []
        while any(remaining.values()):

            def sample(runner):
                left = runner.env.unwrapped.call("remaining")[0]
                if left == 0:
                    return runner.worker_index, [], runner.get_metrics(), 0
                episodes = runner.sample(num_episodes=min(chunk, left), explore=True)
                left = runner.env.unwrapped.call("remaining")[0]
                return runner.worker_index, episodes, runner.get_metrics(), left

            active = [rid for rid, n in remaining.items() if n > 0]
            results = self.env_runner_group.foreach_env_runner(
                sample, local_env_runner=local, remote_worker_ids=None if local else active
            )
            episodes = []
            runner_metrics = []
            answered = set()
            for rid, eps, metrics, left in results:
                answered.add(rid)
                remaining[rid] = left
                episodes.extend(eps)
                runner_metrics.append(metrics)
            for rid in set(active) - answered:  # died during this round
                self._lose_subtasks(rid, remaining.pop(rid))
            self.metrics.aggregate(runner_metrics, key=ENV_RUNNER_RESULTS)
            episodes = [e for e in episodes if not e.get_infos(-1).get("subtask_idle", False)]
            if episodes:
                records.append(_subtask_records(episodes))
                self._learn(episodes)
        if not records:
            raise RuntimeError("no sub-task of this repetition was traversed: every env runner failed")
        return {k: np.concatenate([r[k] for r in records]) for k in records[0]}

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

    def _learn(self, episodes) -> None:
        new_steps = sum(len(e) for e in episodes)
        self.agent_updater.add(episodes)
        num_updates = self.gradient_steps.on_env_steps(new_steps)
        if num_updates == 0:
            return
        lifetime = self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)
        timesteps = {
            NUM_ENV_STEPS_SAMPLED_LIFETIME: lifetime,
            NUM_AGENT_STEPS_SAMPLED_LIFETIME: lifetime,
        }
        learner_results = self.agent_updater.update(num_updates, timesteps)
        if learner_results:
            self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        self.env_runner_group.sync_weights(
            from_worker_or_learner_group=self.learner_group, inference_only=True
        )

    # ------------------------------------------------------------------------------- evaluation
    def _evaluation_plan(self, n: int) -> dict[str, Any]:
        """How the planned evaluation runs: the planner (anything with `sample(starts, goals,
        deterministic=True)`), the steps per waypoint of layer k, optionally `hop_limits(waypoints)`
        (per-task, per-hop steps, [N, P - 1]) and a total cap. SoRB returns its graph."""
        return {
            "planner": self.planner,
            "step_limit_of": lambda k: self.rules.step_limit_of(k, self.config.tree_depth),
            "planned_total_steps": None,
        }

    def _evaluate_mastery(self, policy, planner, split: str) -> None:
        """On an env with its own episode-level measure (the walker's mastered track distributions,
        `mastery`): the agent following the plan of the first test task (all share one task there), or
        alone without a planner, on the tracks of `split`."""
        mastery = getattr(self.goal_env.unwrapped, "mastery", None)
        if mastery is None:
            return
        path = None
        if planner is not None:
            path = planner.sample(self.test_starts[:1], self.test_goals[:1], deterministic=True)[0]
        result = mastery(policy, path, with_delta=self.rules.agent_input == "state_goal_delta", split=split)
        self._log_eval(split, keys.EVAL_MASTERED, result.mastered_fraction)
        self._log_eval(split, keys.EVAL_ENV_RETURN, float(result.returns.mean()))

    def _task_reward(self) -> float:
        """R: what reaching a whole task's goal is worth (the goal env's reward x reward_scale)."""
        return float(getattr(self.goal_env.unwrapped, "goal_reward", 1.0)) * self.rules.reward_scale

    def _log_eval(self, split: str, key: str, value: float) -> None:
        """An evaluation figure of `split`: `key` (copilot/eval/...) for test, its validation twin else."""
        name = key if split == "test" else keys.validation_key(key)
        self.metrics.log_value(keys.metric_path(name), value, window=1)

    def _evaluate(self) -> None:
        """The validation tasks (headline figures only: what searchers read), then the test tasks
        (everything the report shows), with the same plan and policy."""
        n = min(self.config.eval_num_tasks, min(len(s) for s, _ in self.eval_tasks.values()))
        plan = self._evaluation_plan(n)
        if plan is None:  # nothing to evaluate yet (SoRB's pre-training)
            return
        env_steps = int(self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))
        for split in EVAL_SPLITS:
            self._evaluate_split(split, n, plan, env_steps)

    def _evaluate_split(self, split: str, n: int, plan: dict[str, Any], env_steps: int) -> None:
        cfg = self.config
        test = split == "test"
        starts, goals = (x[:n] for x in self.eval_tasks[split])
        module = self.get_module(DEFAULT_MODULE_ID)
        seed = (0 if cfg.seed is None else int(cfg.seed)) + self.iteration
        policies = {
            DETERMINISTIC: ModulePolicy(module),
            SAMPLED: ModulePolicy(module, sampled=True, seed=seed),
        }
        # The headline action goes first: it also drives the sub-goal tree figure's rollouts. The
        # validation tasks get the headline action only.
        policies = {cfg.eval_action: policies[cfg.eval_action], **(policies if test else {})}
        result = evaluate_copilot(
            goal_env_id=cfg.goal_env,
            goal_env_config=cfg.goal_env_config,
            policies=policies,
            starts=starts,
            goals=goals,
            depth=cfg.tree_depth,
            tau_max=cfg.tau_max,
            tree_tasks=min(cfg.eval_tree_tasks, n) if test else 0,
            with_delta=self.rules.agent_input == "state_goal_delta",
            **plan,
        )
        headline = result.headline(cfg.eval_action)
        for key, value in headline.items():
            self._log_eval(split, keys.EVAL_PREFIX + key, value)
        # The figure every algorithm reports: CO-PILOT's is the agent following the plan.
        success = headline[keys.eval_leaf(keys.SUCCESS_PLANNED)]
        self._log_eval(split, keys.EVAL_SUCCESS, success)
        self._log_eval(split, keys.EVAL_SUCCESS_AUC, self.success_curves[split].add(env_steps, success))
        reached = headline[keys.eval_leaf(keys.REACHED_PLANNED)]
        self._log_eval(split, keys.EVAL_RETURN, self._task_reward() * reached)
        self._evaluate_mastery(policies[cfg.eval_action], plan["planner"], split)
        if not test:
            return
        for action, values in result.by_action.items():
            for key, value in values.items():
                self.metrics.log_value(
                    keys.metric_path(keys.eval_by_action(keys.EVAL_PREFIX + key, action)), value, window=1
                )
        self.metrics.log_value(
            keys.metric_path(keys.PLANNED_COLLISION_FREE), result.plan_collision_free, window=1
        )
        if plan["planner"] is not None:  # without a plan, [s0, g] is not a path worth scoring
            if cfg.eval_rrt_reference_s > 0 and self._rrt_reference is None:
                seed = 0 if cfg.seed is None else int(cfg.seed)
                self._rrt_reference = rrt_reference(
                    cfg.goal_env, cfg.goal_env_config, n, cfg.eval_rrt_reference_s, seed
                )
            figures = path_metrics(result.plan_scores, self._planner_checks.count, self._rrt_reference)
            for key, value in figures.items():
                self.metrics.log_value(keys.metric_path(key), value, window=1)
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
    @override(Algorithm)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict[str, Any]:
        """Algorithm's state plus CO-PILOT's driver-side state under the "copilot" key."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        state[_STATE_KEY] = {
            "planner": None if self.planner is None else self.planner.state_dict(),
            "cost_model": self.cost_model.state_dict(),
            "alpha_clock": self.alpha_clock.state_dict(),
            "rng": self._rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "agent_updater": self.agent_updater.get_state(),
            "gradient_steps": self.gradient_steps.get_state(),
            "planner_phases": self._planner_phases,
            "planner_checks": self._planner_checks.count,
            "warm_started": self._warm_started,
            "eval_schedule": self.eval_schedule.get_state(),
            "success_curves": {split: c.get_state() for split, c in self.success_curves.items()},
            "privileged": dict(self._privileged),
        }
        return state

    @override(Algorithm)
    def set_state(self, state: dict[str, Any]) -> None:
        """Algorithm's `set_state`, then CO-PILOT's driver-side state when the state has it."""
        super().set_state(state)
        own = state.get(_STATE_KEY)
        if own is None:
            return
        if self.planner is not None:
            self.planner.load_state_dict(own["planner"])
        self.cost_model.load_state_dict(own["cost_model"])
        self.alpha_clock.load_state_dict(own["alpha_clock"])
        self._rng.bit_generator.state = own["rng"]
        torch.set_rng_state(own["torch_rng"])
        self.agent_updater.set_state(own["agent_updater"])
        self.gradient_steps.set_state(own["gradient_steps"])
        self._planner_phases = int(own.get("planner_phases", 0))
        self._planner_checks.count = int(own.get("planner_checks", 0))
        self._warm_started = bool(own.get("warm_started", True))
        self.eval_schedule.set_state(own.get("eval_schedule", {}))
        for split, curve in own.get("success_curves", {}).items():
            self.success_curves[split].set_state(curve)
        self._privileged.update(own.get("privileged", {}))


def dtau_tuples(subtasks: dict[str, np.ndarray], failed_subtask_cost: str, distance, step_distance: float):
    """(starts, ends, steps) of the D_tau tuples of finished sub-tasks (the `_subtask_records` columns).

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


def _traversal_stats(subtasks: dict[str, np.ndarray], depth: int) -> dict[str, float]:
    """Per layer: mean steps per sub-task, and how often the layer's traversal reached g."""
    out = {}
    layers, reached = subtasks["layer"], subtasks["reached"]
    for k in range(depth + 1):
        in_layer = layers == k
        if not in_layer.any():
            continue
        out[keys.AGENT_STEPS_LAYER + str(k)] = float(subtasks["steps"][in_layer].mean())
        # A layer's traversal succeeds when its last sub-task (the final goal g) is reached.
        last = in_layer & (subtasks["index"] == 2**k)
        if last.any():
            out[keys.AGENT_SUCCESS_LAYER + str(k)] = float(reached[last].mean())
        out[keys.AGENT_SUBTASK_SUCCESS_LAYER + str(k)] = float(reached[in_layer].mean())
    return out


def _subtask_records(episodes) -> dict[str, np.ndarray]:
    """(start, end, steps, layer, ...) of every finished sub-task, read off its last info."""
    infos = [e.get_infos(-1) for e in episodes]
    return {
        "start": np.stack([i["subtask_start"] for i in infos]).astype(np.float32),
        "end": np.stack([i["subtask_end"] for i in infos]).astype(np.float32),
        "goal": np.stack([i["subtask_goal"] for i in infos]).astype(np.float32),
        "steps": np.array([i["subtask_steps"] for i in infos], np.int64),
        "layer": np.array([i["subtask_layer"] for i in infos], np.int64),
        "index": np.array([i["subtask_index"] for i in infos], np.int64),
        "task": np.array([i["subtask_task"] for i in infos], np.int64),
        "reached": np.array([i["subtask_reached"] for i in infos], bool),
        "collided": np.array([i.get("subtask_collided", False) for i in infos], bool),
        "reset_to_state": np.array([i.get("subtask_reset_to_state", False) for i in infos], bool),
        "map_queries": np.array([i.get("subtask_map_queries", 0) for i in infos], np.int64),
    }
