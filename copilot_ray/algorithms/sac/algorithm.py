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

    curriculum.prepare()                           CO-PILOT: the planner's warm start, once
    tasks    <- task_batch_size distinct training tasks (s0, g), or the batch an iteration left unfinished
                (a curriculum's planner may learn from more: the agent traverses the first ones)
    repeat for its remaining repetitions (`repetitions`: 1 here; CO-PILOT's b):
        trees    <- [s0, g], or curriculum.trees(tasks)   CO-PILOT: a planner phase
        traverse the trees on the env runners          one episode per sub-task, SAC updates in between
        curriculum.learn(sub-tasks)                    CO-PILOT: D_tau, tau_hat, alpha
        stop early, keeping the batch, past an env-step evaluation point or the env-step budget, or
        where a stop was asked for (`heartbeat.request_stop`: train's Ctrl-C and SIGTERM)
    log; evaluate when due (validation and test tasks)

Ending an iteration at the repetition that passes an evaluation point (`eval_every_env_steps`) keeps a
method with long iterations (CO-PILOT: b x its trees) on the same evaluation cadence as one with short
ones; the sequence of draws, planner phases and traversals is the same as without it.

HER is a replay buffer, as in Stable-Baselines3: `gc_sac.HindsightReplayBuffer` relabels goals when a
batch is sampled and recomputes rewards as the goal env's `compute_reward` / `compute_terminated` under
the same `TraversalRules.reward` the env runners use would (`DeviceRelabelledReward`, tested against them), so a relabelled transition is rewarded exactly as
a real one reaching that goal would be.
"""

from __future__ import annotations

import copy
import difflib
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
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
)
from ray.tune.registry import register_env

from copilot_ray import keys
from copilot_ray.algorithms.gc_sac import (
    FlatTransitionBuffer,
    GoalLayout,
    GradientStepSchedule,
    HindsightReplayBuffer,
    use_fast_learner,
    uses_fast_learner,
)
from copilot_ray.algorithms.local_logdir import LocalLogdir
from copilot_ray.algorithms.sac import settings as agent_settings
from copilot_ray.algorithms.sac.agent_updates import (
    FastLearnerUpdater,
    FusedLearnerUpdater,
    StockLearnerUpdater,
    fused_update,
    local_learner,
    replay_capacity,
)
from copilot_ray.algorithms.sac.planned_evaluation import PlannedEvaluation
from copilot_ray.algorithms.sac.relabel_reward import DeviceRelabelledReward
from copilot_ray.algorithms.sac.runner_traversal import RunnerTraversal
from copilot_ray.algorithms.sac.traversal_channel import (
    Subtasks,
    traversal_stats,
)
from copilot_ray.algorithms.sac.traversal_diagnostics import traversal_diagnostics
from copilot_ray.algorithms.sac.traversal_env import (
    RULE_KEYS,
    TRAVERSAL_ENV_ID,
    TraversalRules,
    make_traversal_env,
)
from copilot_ray.algorithms.sac.traversal_runner import TraversalEnvRunner
from copilot_ray.envs import make
from copilot_ray.evaluation import AgentEvaluation
from copilot_ray.heartbeat import Heartbeat
from copilot_ray.planning.curriculum import Curriculum
from copilot_ray.planning.health import check_finite, fill_nan, injected_fault
from copilot_ray.planning.path_metrics import RRTReference
from copilot_ray.registry import RunContext
from copilot_ray.settings import Setting, check, keyword_arguments, route

_STATE_KEY = "goal_sac"


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
        # The training episodes' own length (the agent-only baselines' setting; null: tau_max).
        self.train_episode_steps = agent_settings.SETTINGS["train_episode_steps"].default
        # n_sampled_goal 0: plain SAC on the flat buffer (no relabelling, no goal bookkeeping).
        self.her: dict[str, Any] = {"n_sampled_goal": 0, "goal_selection": "future"}
        # How the fast learner runs its updates on a GPU, not what it learns: `use_fast_learner`'s
        # keyword arguments cuda_graph and compile_update, applied by validate(). (`fused_update` and
        # `lean_traversal`, the paths on any device, are settings.)
        self.fast_learner_options: dict[str, Any] = {}
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
        """`use_fast_learner`'s keyword arguments: the `fused_update` setting and `fast_learner_options`,
        each key one it takes (a ValueError names one it does not)."""
        known = ("cuda_graph", "compile_update")
        for key, value in self.fast_learner_options.items():
            if key not in known:
                why = " (a setting: config.agent(fused_update=...))" if key == "fused_update" else ""
                raise ValueError(
                    f"{type(self).__name__}: fast_learner_options[{key!r}]={value!r} is invalid: known keys are "
                    f"{list(known)}{why}"
                )
        return {"fused_update": self.fused_update, **self.fast_learner_options}

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

    def make_curriculum(
        self, env, train_tasks, probe_starts, reachable_length, rng, seed
    ) -> Curriculum | None:
        """What the agent traverses instead of its whole tasks (`copilot_ray.planning.curriculum`): none
        here (SAC, HER, SoRB traverse [s0, g]); CO-PILOT and the RRT* curriculum give theirs. Built last
        in the agent's setup, from the run's `rng`."""
        return None


class HERConfig(GoalSACConfig):
    """`GoalSACConfig` with hindsight relabelling on at SB3's defaults (`algorithm: her`)."""

    SETTINGS: ClassVar[Mapping[str, Setting]] = {
        **agent_settings.SETTINGS,
        **{s.key: s for s in agent_settings.HINDSIGHT},
    }
    NESTED: ClassVar[tuple[str, ...]] = ("her",)


class GoalSAC(LocalLogdir, RunnerTraversal, PlannedEvaluation, SAC):
    """Goal-conditioned SAC on training tasks, or on the trees of its curriculum (`self.curriculum`, from
    the config: CO-PILOT's planner, the RRT* curriculum); HER when `her["n_sampled_goal"]` > 0 (module
    docstring). Logs `copilot/eval/success` = success on the test tasks: the agent following the
    curriculum's plan, or alone (`tau_max` steps; then `success_direct` and `success_planned` agree)."""

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
        self.test_starts, self.test_goals = env.tasks("test")
        # Privileges used so far (copilot_ray.privileges): resets to a missed sub-goal and the map
        # queries behind them (after_failure="restart"); collision checks: `_collision_checks()`.
        self._privileged = {"resets": 0, "map_queries": 0}
        self.rules = cfg.traversal_rules()
        # Validation tasks for searchers and probes, test tasks for reports: both at every evaluation,
        # measured as every agent-based method is (copilot_ray.evaluation.AgentEvaluation).
        self.evaluation = AgentEvaluation(
            env,
            cfg.eval_num_tasks,
            cfg.eval_action,
            cfg.eval_interval,
            cfg.eval_every_env_steps,
            self._task_reward(),
        )
        self._subtasks_lost = 0  # this iteration's, taken by env runners that died (AGENT_SUBTASKS_LOST)
        # The task batch in progress and its repetitions done (an iteration may end mid-batch); checkpointed.
        self._batch: np.ndarray | None = None
        self._batch_done = 0
        self._update_seconds, self._updates_done = 0.0, 0
        self.heartbeat = Heartbeat()  # a line every few seconds inside an iteration (`train` prints it)
        self.iteration_done = False  # a seed stack ran this iteration's steps (training_step)
        self.agent_updater = self._make_agent_updater()
        # Carries the fraction of a gradient step from one call to the next, so a ratio like 0.3 is
        # exact over the run instead of rounded per sampling round.
        self.gradient_steps = GradientStepSchedule(
            cfg.utd_ratio(), learning_starts=cfg.num_steps_sampled_before_learning_starts
        )
        self._rrt_cache: RRTReference | None = None  # computed at the first evaluation that needs it
        self.curriculum = cfg.make_curriculum(
            env,
            (self.train_starts, self.train_goals),
            self.test_starts,
            self._reachable_length,
            self._rng,
            seed,
        )

    def _make_agent_updater(self):
        """What turns sampled episodes into SAC gradient steps (agent_updates.py): the fused update on
        the learner's device (`device_replay` there), else the same replay sampled on the host for
        `fused_update=False`, else RLlib's stock path."""
        cfg = self.config
        seeds = [int(cfg.seed or 0)]
        if fused_update(cfg):
            device = local_learner(cfg, self.learner_group).device
            return FusedLearnerUpdater(cfg, self.learner_group, self.device_replay(device, seeds))
        if not cfg.fast_learner:
            return StockLearnerUpdater(cfg, self.learner_group, self.local_replay_buffer)
        return FastLearnerUpdater(cfg, self.learner_group, self.device_replay(torch.device("cpu"), seeds))

    def device_replay(self, device: torch.device, seeds: list[int], dims: tuple[int, int] | None = None):
        """The agent's replay on `device` with a ring per seed (a run's one seed, or a stack's seeds):
        HER's relabelling buffer, its reward computed on the device, where the agent relabels; else
        flat transitions, allocated at the first episodes unless `dims` (observation, action) are given
        (a stack's: a seed's checkpoint restores into its ring before any episode)."""
        cfg = self.config
        if not cfg.uses_hindsight_buffer():
            return FlatTransitionBuffer(replay_capacity(cfg), device, *(dims or (None, None)), seeds=seeds)
        return HindsightReplayBuffer(
            replay_capacity(cfg),
            self.goal_layout(),
            DeviceRelabelledReward(self.goal_env.unwrapped, self.rules, device),
            n_sampled_goal=cfg.her["n_sampled_goal"],
            goal_selection=cfg.her["goal_selection"],
            device=device,
            seeds=seeds,
        )

    def goal_layout(self) -> GoalLayout:
        """Where observation and goal sit in the agent's flat input."""
        env = self.goal_env.unwrapped
        return GoalLayout(
            obs_dim=int(self.goal_env.observation_space["observation"].shape[0]),
            goal_dim=int(env.goal_space.shape[0]),
            with_delta=self.rules.agent_input == "state_goal_delta",
        )

    # --------------------------------------------------------------------------- training step
    @override(DQN)
    def training_step(self) -> None:
        """One iteration: `iteration_steps`, its traversals run on this algorithm's env runners. A seed
        stack (`seed_stack.SeedStack`) runs its seeds' iterations together, their traversals in one
        loop, before it calls each seed's `train()`: then the iteration is done already."""
        if self.iteration_done:
            self.iteration_done = False
            return
        steps = self.iteration_steps()
        try:
            request = next(steps)
            while True:
                request = steps.send(self._traverse(*request))
        except StopIteration:
            return

    def iteration_steps(self):
        """One iteration (module docstring) as a generator: it yields each repetition's traversal,
        (trees, task ids), and is sent its `Subtasks`. It draws the tasks (or takes up the unfinished
        batch), runs their remaining of `repetitions` traversals with SAC updates in between, ending early, with the batch
        kept for the next iteration, past an env-step evaluation point or the run's env-step budget, or
        where a stop was asked for through `self.heartbeat` (an iteration a stop cuts short is evaluated
        only at an env-step point: on the iterations cadence the one that finishes its batch is); logs,
        evaluates when due. A curriculum plans the trees of each repetition and learns from its finished
        sub-tasks; its warm start pauses between phases on a stop (StopRequested)."""
        cfg = self.config
        curriculum = self.curriculum
        self._check_learned("at the start of the iteration", drill=True)
        if curriculum is not None:
            self._log(curriculum.prepare(self.iteration + 1, self._rng, self.heartbeat))
        self._subtasks_lost = 0
        self._update_seconds, self._updates_done = 0.0, 0  # this iteration's SAC updates (_learn)
        if self._batch is None:
            self._batch, self._batch_done = self._draw_tasks(), 0
        idx = self._batch
        n_tasks = min(cfg.task_batch_size, len(idx))  # the agent's tasks: the first of the batch
        stats: dict[str, list[float]] = defaultdict(list)  # averaged over the repetitions
        timing: dict[str, float] = defaultdict(float)
        self.heartbeat.boundary = "the end of this repetition"
        stopped = False
        while self._batch_done < cfg.repetitions:
            if self.heartbeat.stop_requested:
                # A stop (train's Ctrl-C, SIGTERM) ends the iteration between repetitions, where the batch
                # and its repetitions done are whole: a resumed run redoes nothing and takes no iteration
                # past the bound --check gives.
                stopped = True
                break
            # What the watch repeats until the traversal's first beat (not the last iteration's evaluation).
            self.heartbeat.beat(self._traversal_progress)
            if curriculum is None:
                trees = np.stack([self.train_starts[idx], self.train_goals[idx]], axis=1)
            else:
                t0 = time.perf_counter()
                trees, figures = curriculum.trees(
                    self.train_starts[idx], self.train_goals[idx], n_tasks, self._rng
                )
                timing["planner_s"] += time.perf_counter() - t0
                for key, value in figures.items():
                    stats[key].append(value)
            t0 = time.perf_counter()
            subtasks = yield trees[:n_tasks], idx[:n_tasks]
            timing["agent_s"] += time.perf_counter() - t0
            self._privileged["resets"] += int(subtasks["reset_to_state"].sum())
            self._privileged["map_queries"] += int(subtasks["map_queries"].sum())
            for key, value in self._traversal_diagnostics(subtasks).items():
                stats[key].append(value)
            if curriculum is not None:
                t0 = time.perf_counter()
                for key, value in curriculum.learn(subtasks, self._rng).items():
                    stats[key].append(value)
                timing["cost_model_s"] += time.perf_counter() - t0
            for key, value in traversal_stats(subtasks, cfg.tree_depth).items():
                stats[key].append(value)
            self._batch_done += 1
            env_steps = self._env_steps()
            if cfg.env_step_budget and env_steps >= cfg.env_step_budget:
                # The run ends with this iteration: its other repetitions would only be experience past
                # the budget that a method with short iterations never gets.
                break
            if self.evaluation.schedule.point_passed(env_steps):
                break  # evaluate now, on the cadence; the batch's other repetitions come next iteration
        if self._batch_done >= cfg.repetitions:
            self._batch = None
        self._check_learned("after its planner and cost-model updates")

        self._log({key: float(np.mean(values)) for key, values in stats.items()})
        self._log({keys.AGENT_SUBTASKS_LOST: self._subtasks_lost, keys.AGENT_SAC_UPDATES: self._updates_done})
        if curriculum is not None:
            # The planner and cost-model phases should stay a small share of the iteration.
            planning = timing["planner_s"] + timing["cost_model_s"]
            self._log({keys.PLANNING_SHARE: planning / max(planning + timing["agent_s"], 1e-9)})
        # agent_s is the whole traversal (env stepping + SAC updates); the updates' part beside it.
        timing["agent_updates_s"] = self._update_seconds
        try:
            q_mean = float(self.metrics.peek((LEARNER_RESULTS, DEFAULT_MODULE_ID, "qf_mean")))
        except KeyError:  # no learner update yet
            q_mean = None
        if q_mean is not None:
            self._log({keys.DIAG_Q_MEAN: q_mean})
        self._log({keys.TIME_PREFIX + key: value for key, value in timing.items()})
        whole = not (stopped and self._batch is not None)
        if self.evaluation.schedule.due(self.iteration + 1, self._env_steps(), whole=whole):
            self.heartbeat.boundary = "the end of this evaluation"
            t = time.perf_counter()
            self._evaluate()
            self._log({keys.TIME_PREFIX + "eval_s": time.perf_counter() - t})
        # After the evaluation: a method that plans its evaluation tasks with the map (SoRB with the map,
        # the RRT* curriculum) counts those checks, and those tasks, in the iteration that made them.
        if curriculum is not None:
            self._log(curriculum.summary())
        self._log(
            {
                keys.PRIVILEGE_COLLISION_CHECKS: self._collision_checks(),
                keys.PRIVILEGE_RESETS: self._privileged["resets"],
                keys.PRIVILEGE_MAP_QUERIES: self._privileged["map_queries"],
            }
        )

    def _log(self, figures: Mapping[str, float]) -> None:
        """This iteration's figures (full metric names, `copilot_ray.keys`)."""
        for key, value in figures.items():
            self.metrics.log_value(keys.metric_path(key), value, window=1)

    def _check_learned(self, when: str, drill: bool = False) -> None:
        """The curriculum's learned weights are finite (`planning.health`), else the run stops naming
        them; `drill`: first the fault drill's NaN, if one is set for this iteration (none in real runs)."""
        parts = {} if self.curriculum is None else self.curriculum.learned_parts()
        if not parts:
            return
        if drill and (broken := injected_fault(self.iteration + 1, self.config.seed)) is not None:
            fill_nan(parts.get(broken, ()))
        check_finite(parts, self.iteration + 1, when)

    def _env_steps(self) -> int:
        return int(self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))

    def _draw_tasks(self) -> np.ndarray:
        """Indices of this iteration's training tasks: task_batch_size distinct ones, or as many as the
        curriculum's planner learns from (the agent traverses the first task_batch_size); at most all."""
        n = min(self.config.task_batch_size, len(self.train_starts))
        if self.curriculum is not None:
            n = min(self.curriculum.tasks_to_draw(n), len(self.train_starts))
        return self._rng.choice(len(self.train_starts), size=n, replace=False)

    def _collision_checks(self) -> int:
        """Ground-truth collision checks spent so far (a privilege): the curriculum's planner's."""
        return 0 if self.curriculum is None else self.curriculum.collision_checks

    def _reachable_length(self, layer: int) -> float:
        """The longest segment a layer-`layer` sub-task can cover (step limit x step + radius)."""
        env = self.goal_env.unwrapped
        steps = self.rules.step_limit_of(layer, self.config.tree_depth)
        return steps * float(env.nominal_step_distance) + float(getattr(env, "success_radius", 0.0))

    def _traversal_diagnostics(self, subtasks: Subtasks) -> dict[str, float]:
        env = self.goal_env.unwrapped
        return traversal_diagnostics(
            subtasks,
            distance=env.goal_distance,
            success_radius=float(getattr(env, "success_radius", 0.0)),
        )

    # ------------------------------------------------------------------------------ checkpoints
    @override(Algorithm)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict[str, Any]:
        """Algorithm's state plus the driver-side state under "goal_sac" (and the curriculum's, under its
        `state_key`: "copilot" for CO-PILOT's, as before it was a component)."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        state[_STATE_KEY] = {
            "rng": self._rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),  # RLlib's own sampling loop draws from it
            "action_noise": self._action_noise_state(),
            "agent_updater": self.agent_updater.get_state(),
            "gradient_steps": self.gradient_steps.get_state(),
            **self.evaluation.get_state(),  # its schedule and success curves
            "privileged": dict(self._privileged),
            "batch": None
            if self._batch is None
            else {"tasks": self._batch.tolist(), "done": self._batch_done},
        }
        if self.curriculum is not None:
            state[self.curriculum.state_key] = self.curriculum.state_dict()
        return state

    def _action_noise_state(self) -> torch.Tensor | None:
        """The local env runner's exploration-noise generator (the lean loop's), None without one."""
        runner = self.env_runner_group.local_env_runner
        return runner.action_noise.get_state() if isinstance(runner, TraversalEnvRunner) else None

    @override(Algorithm)
    def set_state(self, state: dict[str, Any]) -> None:
        """Algorithm's `set_state`, then the driver-side state when the state has it."""
        super().set_state(state)
        own = state.get(_STATE_KEY)
        if own is None:
            return
        self._rng.bit_generator.state = own["rng"]
        torch.set_rng_state(own["torch_rng"])
        if own.get("action_noise") is not None:
            self.env_runner_group.local_env_runner.action_noise.set_state(own["action_noise"])
        self.agent_updater.set_state(own["agent_updater"])
        self.gradient_steps.set_state(own["gradient_steps"])
        self.evaluation.set_state(own)
        self._privileged.update(own.get("privileged", {}))
        batch = own.get("batch")  # absent in checkpoints from before iterations could end mid-batch
        self._batch = None if batch is None else np.asarray(batch["tasks"], dtype=np.int64)
        self._batch_done = 0 if batch is None else int(batch["done"])
        if self.curriculum is not None and self.curriculum.state_key in state:
            self.curriculum.load_state_dict(state[self.curriculum.state_key])
