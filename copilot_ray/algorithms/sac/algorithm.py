"""Goal-conditioned SAC on training tasks: `GoalSACConfig` and `GoalSAC`, the base every agent-based
method here builds on (HER and SoRB add a replay buffer and a search; CO-PILOT adds its planner, cost
model and sub-task curriculum in `copilot_ray.algorithms.copilot`).

    config = GoalSACConfig().environment("maze-point", env_config={"layout": "four-rooms"})
    config.hindsight(n_sampled_goal=4)          # HER; without it: plain SAC
    algo = config.build_algo()

An RLlib `SAC` whose env runners sample the traversal env (traversal_env.py: one episode = one sub-task;
here every "tree" is the task itself, [s0, g]), whose learner is the fast goal-conditioned SAC learner
(`copilot_ray.algorithms.gc_sac`, or RLlib's stock one with `fast_learner=False`), and which evaluates on
the env's validation and test tasks. One `training_step`:

    tasks    <- task_batch_size distinct training tasks (s0, g), or the batch an iteration left unfinished
    repeat for its remaining repetitions (`repetitions`: 1 here; CO-PILOT's b):
        trees    <- _trees(tasks)                      [s0, g]; CO-PILOT: a planner phase
        traverse the trees on the env runners          one episode per sub-task, SAC updates in between
        _after_traversal(sub-tasks)                    nothing here; CO-PILOT: D_tau, tau_hat, alpha
        stop early, keeping the batch, past an env-step evaluation point or the env-step budget
    log; evaluate when due (validation and test tasks)

Ending an iteration at the repetition that passes an evaluation point (`eval_every_env_steps`) keeps a
method with long iterations (CO-PILOT: b x its trees) on the same evaluation cadence as one with short
ones; the sequence of draws, planner phases and traversals is the same as without it.

HER is a replay buffer, as in Stable-Baselines3: `gc_sac.HindsightReplayBuffer` relabels goals when a
batch is sampled and recomputes rewards with the goal env's `compute_reward` / `compute_terminated` under
the same `TraversalRules.reward` the env runners use, so a relabelled transition is rewarded exactly as
a real one reaching that goal would be.
"""

from __future__ import annotations

import copy
import difflib
import logging
import time
from collections import defaultdict
from collections.abc import Mapping
from typing import Any, ClassVar

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
from copilot_ray.algorithms.gc_sac import (
    DeviceHindsightBuffer,
    GoalLayout,
    GradientStepSchedule,
    HindsightReplayBuffer,
    use_fast_learner,
    uses_fast_learner,
)
from copilot_ray.algorithms.sac import settings as agent_settings
from copilot_ray.algorithms.sac.agent_updates import (
    FastLearnerUpdater,
    FusedLearnerUpdater,
    fused_update,
    local_learner,
    make_agent_updater,
    replay_capacity,
)
from copilot_ray.algorithms.sac.relabel_reward import DeviceRelabelledReward, relabelled_reward
from copilot_ray.algorithms.sac.traversal_diagnostics import traversal_diagnostics
from copilot_ray.algorithms.sac.traversal_env import (
    RULE_KEYS,
    TRAVERSAL_ENV_ID,
    TraversalRules,
    make_traversal_env,
)
from copilot_ray.algorithms.sac.traversal_runner import TraversalEnvRunner
from copilot_ray.envs import make
from copilot_ray.evaluation import (
    EVAL_SPLITS,
    EvaluationSchedule,
    ModulePolicy,
    SuccessCurve,
    evaluate_copilot,
)
from copilot_ray.planning.path_metrics import path_metrics
from copilot_ray.registry import RunContext
from copilot_ray.settings import Setting, check, keyword_arguments, route

logger = logging.getLogger(__name__)
RUNNER_RESTORE_TIMEOUT_S = 120  # waiting for a failed env runner to come back when none is left
_STATE_KEY = "goal_sac"
DETERMINISTIC, SAMPLED = keys.EVAL_ACTIONS


def register_traversal_env() -> None:
    """Makes the traversal env known to Ray Tune's registry (idempotent, cheap)."""
    register_env(TRAVERSAL_ENV_ID, make_traversal_env)


class GoalSACConfig(SACConfig):
    """RLlib's `SACConfig` plus the goal-conditioned agent's settings (`SETTINGS`, set with `.agent(...)`;
    SAC's own with `.training(...)`) and HER's (`.hindsight(...)`).

    A subclass names its settings table (`SETTINGS`) and the targets it keeps as dicts (`NESTED`: e.g.
    `her.n_sampled_goal` is `config.her["n_sampled_goal"]`); defaults, `from_settings`, `setting_values`
    and the checks in `validate()` are read off them here, once for every agent-based algorithm.
    """

    SETTINGS: ClassVar[Mapping[str, Setting]] = agent_settings.SETTINGS
    NESTED: ClassVar[tuple[str, ...]] = ()
    # What the traversal runs (CO-PILOT sets its own): one [s0, g] "tree" per task, once per iteration.
    tree_depth = 0
    repetitions = 1

    @override(SACConfig)
    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or GoalSAC)
        # One training_step is one task mini-batch (x repetitions): no minimum time or steps.
        self.min_time_s_per_iteration = 0
        self.min_sample_timesteps_per_iteration = 0
        self.num_envs_per_env_runner = 1
        self.num_env_runners = 0
        self.goal_env: str | None = None  # set by validate(): the env the user named
        self.goal_env_config: dict[str, Any] = {}
        self.env_step_budget: int | None = None  # RunContext.env_step_budget: see training_step
        # The tree-traversal readings the traversal env implements (their defaults: no tree here).
        for s in agent_settings.TREE_TRAVERSAL:
            setattr(self, s.key, s.default)
        # n_sampled_goal 0: plain SAC on the flat buffer (no relabelling, no goal bookkeeping).
        self.her: dict[str, Any] = {"n_sampled_goal": 0, "goal_selection": "future"}
        # How the fast learner runs its updates, not what it learns: `use_fast_learner`'s keyword
        # arguments (fused_update, cuda_graph, compile_update), applied by validate().
        self.fast_learner_options: dict[str, Any] = {}
        # Sample the traversal with TraversalEnvRunner's lean loop (False: RLlib's own env runner).
        self.lean_traversal = True
        self._apply({key: s.default for key, s in self.SETTINGS.items() if self._is_value(s)}, defaults=True)

    # ------------------------------------------------------------------ settings by name
    @classmethod
    def _is_value(cls, s: Setting) -> bool:
        """Whether the setting is a value of its own (not one field of a composite, e.g. the alpha
        schedule's `alpha_schedule.start`)."""
        return True

    def _apply(self, values: Mapping[str, Any], defaults: bool = False) -> None:
        """Flat setting values to where they go (`settings.route`): a nested dict's field, RLlib's
        `.training(...)`, or an attribute of the config."""
        for target, fields in route(self.SETTINGS, values).items():
            if target in self.NESTED:
                current = {} if defaults else dict(getattr(self, target, {}))
                setattr(self, target, {**current, **copy.deepcopy(fields)})
            elif target == "training":
                self.training(**fields)
            else:
                for key, value in fields.items():
                    setattr(self, key, copy.deepcopy(value))

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: RunContext) -> GoalSACConfig:
        """A config from flat setting `values` (dotted keys, as in a sweep spec) for one run: what
        sweeps, `train` and benchmarks build (the registry's config entry)."""
        config = (
            cls()
            .environment(run.env_id, env_config=dict(run.env_config))
            .env_runners(num_env_runners=run.num_env_runners)
            # The run's own process (sampling when there are no runners, and the learner) gets the
            # CPUs not taken by runners; validate() sizes torch's thread pool from it.
            .resources(num_cpus_for_main_process=run.num_cpus_for_main_process)
            # The learner (SAC's updates, the batched evaluation's module stays on the runner) on the
            # run's GPU share; RLlib moves the module and each batch there and sizes the trial's bundle.
            .learners(num_gpus_per_learner=run.num_gpus)
            .debugging(seed=run.seed)
        )
        config.env_step_budget = run.env_step_budget
        config._set_values(values)
        return config

    def _set_values(self, values: Mapping[str, Any]) -> None:
        self._refuse_unknown(values, "from_settings")
        self._apply(values)

    def _refuse_unknown(self, names, caller: str) -> None:
        unknown = sorted(set(names) - set(self.SETTINGS))
        if unknown:
            close = difflib.get_close_matches(unknown[0], sorted(self.SETTINGS), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(f"{type(self).__name__}.{caller}: unknown setting {unknown[0]!r}{hint}")

    @keyword_arguments(agent_settings.SETTINGS, ("agent",))
    def agent(self, **settings: Any) -> GoalSACConfig:
        """Sets the agent's settings by name (`SETTINGS` with target "agent"). SAC's own learning
        settings go to `.training(...)`. Values are checked by `validate()`."""
        self._refuse_unknown(settings, "agent")
        training = [k for k in settings if self.SETTINGS[k].target == "training"]
        if training:
            raise ValueError(
                f"{type(self).__name__}.agent: {training[0]} is SAC's: set it with .training(...)"
            )
        self._apply(settings)
        return self

    def hindsight(self, **settings: Any) -> GoalSACConfig:
        """HER's settings: n_sampled_goal (>= 1 relabels; SB3's default 4), goal_selection ("future",
        "final", "episode"). Checked by validate()."""
        known = {s.field for s in agent_settings.HINDSIGHT}
        unknown = sorted(set(settings) - known)
        if unknown:
            raise ValueError(
                f"{type(self).__name__}.hindsight: unknown setting {unknown[0]!r}; known: {sorted(known)}"
            )
        self.her = {**self.her, **settings}
        return self

    def setting_values(self) -> dict[str, Any]:
        """Every setting of `SETTINGS` at its current value (dotted keys)."""
        return {
            key: getattr(self, s.target).get(s.field) if s.target in self.NESTED else getattr(self, key)
            for key, s in self.SETTINGS.items()
            if self._is_value(s)
        }

    # ------------------------------------------------------------------ validation
    @override(SACConfig)
    def validate(self) -> None:
        self._check_settings()
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
            use_fast_learner(
                self, updates_per_env_step=self.utd_ratio(), torch_threads=threads, **self._learner_options()
            )
        if self.lean_traversal and self.env_runner_cls is None:
            self.env_runners(env_runner_cls=TraversalEnvRunner)
        elif not self.lean_traversal and self.env_runner_cls is TraversalEnvRunner:
            self.env_runner_cls = None
        register_traversal_env()
        super().validate()

    def _check_settings(self) -> None:
        """Every setting against its rule, and the combinations, with one message format (`settings.check`)."""
        name = type(self).__name__
        for target in self.NESTED:
            known = {s.field for s in self.SETTINGS.values() if s.target == target}
            unknown = sorted(set(getattr(self, target)) - known)
            if unknown:
                raise ValueError(
                    f"{name}: {target}.{unknown[0]}={getattr(self, target)[unknown[0]]!r} is invalid: "
                    f"known keys are {sorted(known)}"
                )
        values = self.setting_values()
        check({k: self.SETTINGS[k] for k in values}, values, name)
        for involved, _, why in self._combination_problems(values):
            given = " and ".join(f"{key}={values.get(key)!r}" for key in involved)
            raise ValueError(f"{name}: {given} do not go together: {why}")
        if self.her.get("n_sampled_goal", 0) != 0 and "her" not in self.NESTED:
            check(
                {s.key: s for s in agent_settings.HINDSIGHT},
                {f"her.{k}": v for k, v in self.her.items()},
                name,
            )
        if self.uses_hindsight_buffer() and not self.fast_learner:
            raise ValueError(
                f"{name}: fast_learner=False is invalid with hindsight relabelling: the relabelling buffer "
                "feeds the fast learner"
            )
        if not isinstance(self.lean_traversal, bool):
            raise ValueError(
                f"{name}: lean_traversal={self.lean_traversal!r} is invalid: must be True or False"
            )
        if self.num_envs_per_env_runner != 1:
            raise ValueError(
                f"{name}: num_envs_per_env_runner={self.num_envs_per_env_runner!r} is invalid: one sub-task "
                "queue per runner; use 1 and scale with num_env_runners"
            )
        if self.env is None:
            raise ValueError(
                f'{name}: env=None is invalid: call .environment("maze-point", env_config={{...}})'
            )

    def _combination_problems(self, values: Mapping[str, Any]):
        return agent_settings.combination_problems(values)

    def _learner_options(self) -> dict[str, Any]:
        """`fast_learner_options`, each key one `use_fast_learner` takes (a ValueError names one it
        does not)."""
        known = ("fused_update", "cuda_graph", "compile_update")
        for key, value in self.fast_learner_options.items():
            if key not in known:
                raise ValueError(
                    f"{type(self).__name__}: fast_learner_options[{key!r}]={value!r} is invalid: known keys are "
                    f"{list(known)}"
                )
        return dict(self.fast_learner_options)

    # ------------------------------------------------------------------ derived
    def traversal_rules(self) -> TraversalRules:
        """How the agent runs and is rewarded on sub-tasks."""
        return TraversalRules(**{name: getattr(self, name) for name in RULE_KEYS})

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

    def uses_hindsight_buffer(self) -> bool:
        """Whether the agent's replay is the hindsight buffer (HER, or an algorithm that reads states)."""
        return self.her.get("n_sampled_goal", 0) > 0


class HERConfig(GoalSACConfig):
    """`GoalSACConfig` with hindsight relabelling on at SB3's defaults (`algorithm: her`)."""

    SETTINGS: ClassVar[Mapping[str, Setting]] = {
        **agent_settings.SETTINGS,
        **{s.key: s for s in agent_settings.HINDSIGHT},
    }
    NESTED: ClassVar[tuple[str, ...]] = ("her",)


class GoalSAC(SAC):
    """Goal-conditioned SAC on whole training tasks; HER when `her["n_sampled_goal"]` > 0 (module
    docstring). Logs `copilot/eval/success` = success on the test tasks (the agent alone, `tau_max`
    steps), as `success_direct` and `success_planned` (equal here: there is no plan)."""

    @classmethod
    @override(SAC)
    def get_default_config(cls):
        return GoalSACConfig()

    # ----------------------------------------------------------------------------------- setup
    @override(DQN)
    def setup(self, config) -> None:
        """SAC's setup, then the goal env, the task sets, the evaluation's schedule and curves, the agent's
        replay and update schedule."""
        register_traversal_env()
        super().setup(config)
        cfg = self.config
        # A driver-side copy of the goal env: tasks, geometry, evaluation.
        self.goal_env = make(cfg.goal_env, **cfg.goal_env_config)
        env = self.goal_env.unwrapped
        seed = 0 if cfg.seed is None else int(cfg.seed)
        self._rng = np.random.default_rng(seed)
        torch.manual_seed(seed)
        self.train_starts, self.train_goals = env.tasks("train")
        # Validation tasks for searchers and probes, test tasks for reports: both at every evaluation.
        self.eval_tasks = {split: env.tasks(split) for split in EVAL_SPLITS}
        self.test_starts, self.test_goals = self.eval_tasks["test"]
        self.eval_schedule = EvaluationSchedule(cfg.eval_interval, cfg.eval_every_env_steps)
        self.success_curves = {split: SuccessCurve() for split in EVAL_SPLITS}
        # Privileges used so far (copilot_ray.privileges): resets to a missed sub-goal and the map
        # queries behind them (after_failure="restart"); collision checks: `_collision_checks()`.
        self._privileged = {"resets": 0, "map_queries": 0}
        self.rules = cfg.traversal_rules()
        self._subtasks_lost = 0  # this iteration's, taken by env runners that died (AGENT_SUBTASKS_LOST)
        # The task batch in progress and its repetitions done (an iteration may end mid-batch); checkpointed.
        self._batch: np.ndarray | None = None
        self._batch_done = 0
        self._update_seconds, self._updates_done = 0.0, 0
        self.agent_updater = self._make_agent_updater()
        # Carries the fraction of a gradient step from one call to the next, so a ratio like 0.3 is
        # exact over the run instead of rounded per sampling round.
        self.gradient_steps = GradientStepSchedule(
            cfg.utd_ratio(), learning_starts=cfg.num_steps_sampled_before_learning_starts
        )

    def _make_agent_updater(self):
        """What turns sampled episodes into SAC gradient steps (agent_updates.py): with hindsight
        relabelling, the fast learner fed by HER's buffer (on the learner's device, relabelled inside
        the fused step, unless `fused_update=False`)."""
        cfg = self.config
        if not cfg.uses_hindsight_buffer():
            return make_agent_updater(self)
        her = {"n_sampled_goal": cfg.her["n_sampled_goal"], "goal_selection": cfg.her["goal_selection"]}
        if fused_update(cfg):
            device = local_learner(cfg, self.learner_group).device
            reward = DeviceRelabelledReward(self.goal_env.unwrapped, self.rules, device)
            buffer = DeviceHindsightBuffer(
                replay_capacity(cfg), self.goal_layout(), reward, **her, device=device
            )
            return FusedLearnerUpdater(cfg, self.learner_group, buffer)
        buffer = HindsightReplayBuffer(
            replay_capacity(cfg), self.goal_layout(), self.relabelled_reward, **her
        )
        return FastLearnerUpdater(cfg, self.learner_group, buffer)

    def goal_layout(self) -> GoalLayout:
        """Where observation and goal sit in the agent's flat input."""
        env = self.goal_env.unwrapped
        return GoalLayout(
            obs_dim=int(self.goal_env.observation_space["observation"].shape[0]),
            goal_dim=int(env.goal_space.shape[0]),
            with_delta=self.rules.agent_input == "state_goal_delta",
        )

    def relabelled_reward(
        self, next_achieved: np.ndarray, goals: np.ndarray, collisions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(rewards, terminateds) of transitions given new goals: the goal env's reward and
        termination under the traversal rules the env runners apply (one sub-task = one task here)."""
        return relabelled_reward(self.goal_env.unwrapped, self.rules, next_achieved, goals, collisions)

    # --------------------------------------------------------------------------- training step
    @override(DQN)
    def training_step(self) -> None:
        """One iteration (module docstring): draw the tasks (or take up the unfinished batch), run their
        remaining of `repetitions` traversals with SAC updates in between, ending early, with the batch
        kept for the next iteration, past an env-step evaluation point or the run's env-step budget; log,
        evaluate when due. Subclasses plan the trees (`_trees`) and learn from the finished sub-tasks
        (`_after_traversal`)."""
        cfg = self.config
        self._before_iteration()
        self._subtasks_lost = 0
        self._update_seconds, self._updates_done = 0.0, 0  # this iteration's SAC updates (_learn)
        if self._batch is None:
            self._batch, self._batch_done = self._draw_tasks(), 0
        idx = self._batch
        n_tasks = min(cfg.task_batch_size, len(idx))
        stats: dict[str, list[float]] = defaultdict(list)  # averaged over the repetitions
        timing: dict[str, float] = defaultdict(float)
        while self._batch_done < cfg.repetitions:
            trees = self._trees(idx, stats, timing)[:n_tasks]
            t0 = time.perf_counter()
            subtasks = self._traverse(trees, idx[:n_tasks])
            timing["agent_s"] += time.perf_counter() - t0
            self._privileged["resets"] += int(subtasks["reset_to_state"].sum())
            self._privileged["map_queries"] += int(subtasks["map_queries"].sum())
            for key, value in self._traversal_diagnostics(subtasks).items():
                stats[key].append(value)
            self._after_traversal(subtasks, stats, timing)
            for key, value in traversal_stats(subtasks, cfg.tree_depth).items():
                stats[key].append(value)
            self._batch_done += 1
            env_steps = self._env_steps()
            if cfg.env_step_budget and env_steps >= cfg.env_step_budget:
                # The run ends with this iteration: its other repetitions would only be experience past
                # the budget that a method with short iterations never gets.
                break
            if self.eval_schedule.point_passed(env_steps):
                break  # evaluate now, on the cadence; the batch's other repetitions come next iteration
        if self._batch_done >= cfg.repetitions:
            self._batch = None
        self._after_iteration()

        for key, values in stats.items():
            self.metrics.log_value(keys.metric_path(key), float(np.mean(values)), window=1)
        self.metrics.log_value(keys.metric_path(keys.AGENT_SUBTASKS_LOST), self._subtasks_lost, window=1)
        for key, count in (
            (keys.PRIVILEGE_COLLISION_CHECKS, self._collision_checks()),
            (keys.PRIVILEGE_RESETS, self._privileged["resets"]),
            (keys.PRIVILEGE_MAP_QUERIES, self._privileged["map_queries"]),
        ):
            self.metrics.log_value(keys.metric_path(key), count, window=1)
        self._log_iteration(timing)
        # agent_s is the whole traversal (env stepping + SAC updates); the updates' part beside it.
        timing["agent_updates_s"] = self._update_seconds
        self.metrics.log_value(keys.metric_path(keys.AGENT_SAC_UPDATES), self._updates_done, window=1)
        try:
            q_mean = float(self.metrics.peek((LEARNER_RESULTS, DEFAULT_MODULE_ID, "qf_mean")))
        except KeyError:  # no learner update yet
            q_mean = None
        if q_mean is not None:
            self.metrics.log_value(keys.metric_path(keys.DIAG_Q_MEAN), q_mean, window=1)
        for key, value in timing.items():
            self.metrics.log_value(keys.metric_path(keys.TIME_PREFIX + key), value, window=1)
        if self.eval_schedule.due(self.iteration + 1, self._env_steps()):
            t = time.perf_counter()
            self._evaluate()
            self.metrics.log_value(
                keys.metric_path(keys.TIME_PREFIX + "eval_s"), time.perf_counter() - t, window=1
            )

    def _env_steps(self) -> int:
        return int(self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))

    def _draw_tasks(self) -> np.ndarray:
        """Indices of this iteration's training tasks: task_batch_size distinct ones (at most all)."""
        n = min(self.config.task_batch_size, len(self.train_starts))
        return self._rng.choice(len(self.train_starts), size=n, replace=False)

    def _trees(self, idx: np.ndarray, stats, timing) -> np.ndarray:
        """What the agent traverses for tasks `idx`: here the task itself, [s0, g] per task."""
        return np.stack([self.train_starts[idx], self.train_goals[idx]], axis=1)

    def _after_traversal(self, subtasks: dict[str, np.ndarray], stats, timing) -> None:
        """What an algorithm learns from the finished sub-tasks besides SAC's updates (nothing here)."""

    def _before_iteration(self) -> None:
        """Before an iteration's tasks are drawn (nothing here)."""

    def _after_iteration(self) -> None:
        """After its traversals, before its metrics are logged (nothing here)."""

    def _log_iteration(self, timing: Mapping[str, float]) -> None:
        """An algorithm's own per-iteration figures (nothing here)."""

    def _collision_checks(self) -> int:
        """Ground-truth collision checks spent so far (a privilege): none here."""
        return 0

    def _traversal_diagnostics(self, subtasks: dict[str, np.ndarray]) -> dict[str, float]:
        env = self.goal_env.unwrapped
        return traversal_diagnostics(
            subtasks,
            distance=env.goal_distance,
            success_radius=float(getattr(env, "success_radius", 0.0)),
        )

    # ---------------------------------------------------------------------------- traversal
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
                records.append(subtask_records(episodes))
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
        t0 = time.perf_counter()
        learner_results = self.agent_updater.update(num_updates, timesteps)
        self._update_seconds += time.perf_counter() - t0
        self._updates_done += num_updates
        if learner_results:
            self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        self.env_runner_group.sync_weights(
            from_worker_or_learner_group=self.learner_group, inference_only=True
        )

    # ------------------------------------------------------------------------------- evaluation
    def _evaluation_plan(self, n: int) -> dict[str, Any] | None:
        """How the planned evaluation runs: the planner (anything with `sample(starts, goals,
        deterministic=True)`; None: the agent alone), the steps per waypoint of layer k, optionally
        `hop_limits(waypoints)` (per-task, per-hop steps, [N, P - 1]) and a total cap. None: nothing to
        evaluate yet."""
        return {
            "planner": None,
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
        if plan is None:
            return
        env_steps = self._env_steps()
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
            tree_tasks=self._tree_tasks(n) if test else 0,
            with_delta=self.rules.agent_input == "state_goal_delta",
            **plan,
        )
        headline = result.headline(cfg.eval_action)
        for key, value in headline.items():
            self._log_eval(split, keys.EVAL_PREFIX + key, value)
        # The figure every algorithm reports: the agent following its plan (alone without one).
        success = headline[keys.eval_leaf(keys.SUCCESS_PLANNED)]
        self._log_eval(split, keys.EVAL_SUCCESS, success)
        self._log_eval(split, keys.EVAL_SUCCESS_AUC, self.success_curves[split].add(env_steps, success))
        reached = headline[keys.eval_leaf(keys.REACHED_PLANNED)]
        self._log_eval(split, keys.EVAL_RETURN, self._task_reward() * reached)
        self._evaluate_mastery(policies[cfg.eval_action], plan["planner"], split)
        self._log_eval(split, keys.PLANNED_COLLISION_FREE, result.plan_collision_free)
        if not test:
            return
        for action, values in result.by_action.items():
            for key, value in values.items():
                self.metrics.log_value(
                    keys.metric_path(keys.eval_by_action(keys.EVAL_PREFIX + key, action)), value, window=1
                )
        if plan["planner"] is not None:  # without a plan, [s0, g] is not a path worth scoring
            figures = path_metrics(result.plan_scores, self._collision_checks(), self._rrt_reference(n))
            for key, value in figures.items():
                self.metrics.log_value(keys.metric_path(key), value, window=1)
        self._after_test_evaluation(result, env_steps)

    def _tree_tasks(self, n: int) -> int:
        """Test tasks whose sub-goal trees are traversed layer by layer for the tree figure (none here)."""
        return 0

    def _rrt_reference(self, n: int):
        """The RRT* reference the paths' ratios divide by (none here)."""
        return None

    def _after_test_evaluation(self, result, env_steps: int) -> None:
        """What an algorithm keeps of a test evaluation besides its figures (nothing here)."""

    # ------------------------------------------------------------------------------ checkpoints
    @override(Algorithm)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict[str, Any]:
        """Algorithm's state plus the driver-side state under "goal_sac" (and a subclass's, `_own_state`)."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        state[_STATE_KEY] = {
            "rng": self._rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "agent_updater": self.agent_updater.get_state(),
            "gradient_steps": self.gradient_steps.get_state(),
            "eval_schedule": self.eval_schedule.get_state(),
            "success_curves": {split: c.get_state() for split, c in self.success_curves.items()},
            "privileged": dict(self._privileged),
            "batch": None
            if self._batch is None
            else {"tasks": self._batch.tolist(), "done": self._batch_done},
        }
        state.update(self._own_state())
        return state

    @override(Algorithm)
    def set_state(self, state: dict[str, Any]) -> None:
        """Algorithm's `set_state`, then the driver-side state when the state has it."""
        super().set_state(state)
        own = state.get(_STATE_KEY)
        if own is None:
            return
        self._rng.bit_generator.state = own["rng"]
        torch.set_rng_state(own["torch_rng"])
        self.agent_updater.set_state(own["agent_updater"])
        self.gradient_steps.set_state(own["gradient_steps"])
        self.eval_schedule.set_state(own.get("eval_schedule", {}))
        for split, curve in own.get("success_curves", {}).items():
            self.success_curves[split].set_state(curve)
        self._privileged.update(own.get("privileged", {}))
        batch = own.get("batch")  # absent in checkpoints from before iterations could end mid-batch
        self._batch = None if batch is None else np.asarray(batch["tasks"], dtype=np.int64)
        self._batch_done = 0 if batch is None else int(batch["done"])
        self._set_own_state(state)

    def _own_state(self) -> dict[str, Any]:
        """A subclass's driver-side state, under keys of its own (nothing here)."""
        return {}

    def _set_own_state(self, state: dict[str, Any]) -> None:
        """Restores `_own_state` (nothing here)."""


def traversal_stats(subtasks: dict[str, np.ndarray], depth: int) -> dict[str, float]:
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


def subtask_records(episodes) -> dict[str, np.ndarray]:
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
