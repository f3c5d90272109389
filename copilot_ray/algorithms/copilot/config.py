"""CoPilotConfig: RLlib's SACConfig plus CO-PILOT's knobs (`.copilot(...)`).

    config = (
        CoPilotConfig()
        .environment("maze-point", env_config={"layout": "four-rooms"})
        .copilot(tree_depth=5, repetitions=5, alpha_schedule="paper_per_task", tau_max=25)
    )
    algo = config.build_algo()

The user names the goal-conditioned env (`maze-point`); `validate()` swaps in the traversal env that
turns each planned sub-task into one RLlib episode and keeps the goal env's id and config in
`goal_env` / `goal_env_config`.
"""

from __future__ import annotations

import copy
from typing import Any

from ray.rllib.algorithms.algorithm_config import NotProvided
from ray.rllib.algorithms.sac import SACConfig

from copilot_ray.algorithms.copilot.readings import (
    DEFAULTS,
    EVAL_ACTIONS,
    FAILED_SUBTASK_COSTS,
    PRESETS,
    TRAVERSAL_TREES,
)
from copilot_ray.algorithms.copilot.traversal_env import TRAVERSAL_ENV_ID, TraversalRules
from copilot_ray.algorithms.gc_sac import is_fast_gc_sac, use_fast_gc_sac
from copilot_ray.planning import SubgoalPlanner
from copilot_ray.planning.alpha_schedule import AlphaSchedule
from copilot_ray.planning.planner import NOISE_MODES
from copilot_ray.planning.segment_cost import COLLISION_COSTS

# Paper Section 4.1 and, where the paper is silent, the public reference planner (SGT-PG's, which the
# paper's code copies).
DEFAULT_PLANNER = {
    "hidden": [20, 20, 20],  # reference code: 3 x 20 tanh, one net per layer
    "std": 0.05,  # the reference code's absolute std; with noise="relative" a fraction of the parent segment
    "noise": "absolute",
    "lr": 0.005,  # paper 4.1
    "clip": 0.2,  # paper 4.1 (PPO trust region)
    "epochs": 4,
    "num_samples": 16,  # repeated samples per task; their mean cost is the baseline
    # Not in the paper or the reference code: without a gradient-norm clip the PPO update diverged on
    # four-rooms at K = 5 within ~100 planner phases (approx. KL in the millions, NaN weights); with
    # 0.5 (SB3's PPO default) the same run reached 81-83 % collision-free test plans (2 seeds).
    "max_grad_norm": 0.5,
    "target_kl": None,  # optional early stop of the PPO epochs (SB3's target_kl); None: off
    "max_kl": None,  # undo an update whose final approximate KL exceeds this; None: off
    # Annealing (not in the paper): the std moves linearly to std_final over the first
    # std_anneal_phases planner phases (warm-start phases included); std_final None: constant std.
    # CoPilotConfig's default anneals (readings.DEFAULTS).
    "std_final": None,
    "std_anneal_phases": 1000,
}


def build_planner(planner: dict[str, Any], goal_dim: int, depth: int, low, high, seed: int) -> SubgoalPlanner:
    """The planner pi_p from a `planner` settings dict (CoPilotConfig.planner, i.e. DEFAULT_PLANNER's keys)."""
    return SubgoalPlanner(
        goal_dim,
        depth,
        low,
        high,
        hidden=tuple(planner["hidden"]),
        std=planner["std"],
        noise=planner["noise"],
        lr=planner["lr"],
        clip_eps=planner["clip"],
        epochs=planner["epochs"],
        max_grad_norm=planner["max_grad_norm"],
        target_kl=planner["target_kl"],
        max_kl=planner["max_kl"],
        seed=seed,
    )


DEFAULT_COST_MODEL = {
    "hidden": [64, 64],
    "lr": 1e-3,
    "capacity": 200_000,
    "init_euclidean": 50_000,  # paper 4.1
    "fit_steps": 50,
    "batch_size": 256,
}


class CoPilotConfig(SACConfig):
    def __init__(self, algo_class=None):
        from copilot_ray.algorithms.copilot.algorithm import CoPilot

        super().__init__(algo_class=algo_class or CoPilot)
        # --- CO-PILOT (paper Section 4.1 defaults for the maze) ---
        self.tree_depth = 5  # K; T = 2^K. K = 0: no planner (plain goal-conditioned SAC on (s0, g))
        self.repetitions = 5  # b
        self.alpha_schedule: dict[str, Any] = AlphaSchedule.preset("paper_per_task").to_dict()
        self.tau_max = 25
        self.task_batch_size = 30
        # Eq. 11's collision term: "indicator" (the paper: a penalty per colliding segment) or "length"
        # (SGT-PG's reference planner: a penalty per unit of segment length in collision, which tells
        # the planner which way is out of a wall). None: 10 for "indicator" (paper 4.1), 100 for
        # "length" (reference code; a 1/15-wide wall then costs ~6.7, not 0.67).
        self.collision_cost = "indicator"
        self.collision_penalty: float | None = None
        self.planner: dict[str, Any] = dict(DEFAULT_PLANNER)
        self.cost_model: dict[str, Any] = dict(DEFAULT_COST_MODEL)
        self.eval_interval = 1  # iterations between evaluations on held-out test tasks (0: never)
        self.eval_num_tasks = 100  # test tasks per evaluation (the paper's test set has 100)
        self.eval_tree_tasks = 3  # fixed test tasks whose sub-goal trees are saved per evaluation
        self.subtasks_per_sample = 64  # sub-tasks per runner between two learner updates
        self.fast_learner = True  # our flat-buffer SAC learner; False: RLlib's stock SAC path
        # Gradient steps per sampled env step (the update-to-data ratio). None: derived from RLlib's
        # `training_intensity` (replayed / sampled timesteps) when that is set, else 1.0.
        self.updates_per_env_step: float | None = None
        self.goal_env: str | None = None
        self.goal_env_config: dict[str, Any] = {}
        # Tasks in the planner's PPO batch per phase: the iteration's task_batch_size tasks plus other
        # training tasks up to this number (planner phases cost no env steps). With the agent's
        # mini-batch alone (a few tasks, for frequent evaluations) each PPO step over-fits those tasks:
        # measured on four-rooms, collision-free test plans fell from 0.85 to 0.36-0.45 within 10
        # phases on 2 tasks and stayed at 0.80-0.91 on 30 (the paper's mini-batch).
        self.planner_task_batch_size = 30

        # --- RLlib settings CO-PILOT needs ---
        # One training_step is one task mini-batch x b repetitions: no minimum time or steps.
        self.min_time_s_per_iteration = 0
        self.min_sample_timesteps_per_iteration = 0
        # SB3-like SAC defaults ("we use its default hyperparameters", paper 4.1).
        self.actor_lr = 3e-4
        self.critic_lr = 3e-4
        self.alpha_lr = 3e-4
        self.gamma = 0.99
        self.num_steps_sampled_before_learning_starts = 1000
        self.num_envs_per_env_runner = 1
        self.num_env_runners = 0

        # --- readings of the paper's ambiguities: readings.DEFAULTS (the measured ones) ---
        self.preset: str | None = None  # the last preset applied, for the record
        self._apply_preset(DEFAULTS)

    def copilot(
        self,
        *,
        tree_depth: int = NotProvided,
        repetitions: int = NotProvided,
        alpha_schedule: dict | str | AlphaSchedule = NotProvided,
        tau_max: int = NotProvided,
        task_batch_size: int = NotProvided,
        collision_penalty: float | None = NotProvided,
        collision_cost: str = NotProvided,
        planner: dict = NotProvided,
        cost_model: dict = NotProvided,
        eval_interval: int = NotProvided,
        eval_num_tasks: int = NotProvided,
        eval_tree_tasks: int = NotProvided,
        subtasks_per_sample: int = NotProvided,
        fast_learner: bool = NotProvided,
        updates_per_env_step: float = NotProvided,
        preset: str = NotProvided,
        step_limit: str = NotProvided,
        after_failure: str = NotProvided,
        subtask_reward: str = NotProvided,
        reward_scale: float = NotProvided,
        agent_collision: str = NotProvided,
        agent_collision_penalty: float = NotProvided,
        agent_input: str = NotProvided,
        failed_subtask_cost: str = NotProvided,
        traversal_tree: str = NotProvided,
        planner_warm_start: int = NotProvided,
        planner_task_batch_size: int = NotProvided,
        eval_action: str = NotProvided,
    ) -> CoPilotConfig:
        """Sets CO-PILOT's knobs. `planner` and `cost_model` dicts update the defaults key by key.

        preset: a key of PRESETS (e.g. "paper_literal"), applied first; the other arguments of the same
        call override it.

        alpha_schedule: a preset name ("paper_per_task": 0.9 -> 0.1 over every task's b episodes;
        "paper_warm_start": 1 -> 0 over the first two episodes), a dict (see AlphaSchedule), or an
        AlphaSchedule.
        """
        given = {k: v for k, v in locals().items() if k != "self" and v is not NotProvided}
        if "preset" in given:
            name = given.pop("preset")
            if name not in PRESETS:
                raise ValueError(f"CoPilotConfig: preset={name!r} is invalid: use one of {sorted(PRESETS)}")
            self.preset = name
            self._apply_preset(PRESETS[name])
        if "alpha_schedule" in given:
            schedule = given["alpha_schedule"]
            if isinstance(schedule, str):
                schedule = AlphaSchedule.preset(schedule)
            if isinstance(schedule, AlphaSchedule):
                schedule = schedule.to_dict()
            given["alpha_schedule"] = dict(schedule)
        for name in ("planner", "cost_model"):
            if name in given:
                given[name] = {**getattr(self, name), **given[name]}
        for key, value in given.items():
            setattr(self, key, value)
        return self

    def _apply_preset(self, values: dict[str, Any]) -> None:
        for key, value in values.items():
            if key in ("planner", "cost_model"):
                setattr(self, key, {**getattr(self, key), **value})
            else:
                setattr(self, key, copy.deepcopy(value))

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
        if self.fast_learner and not is_fast_gc_sac(self):
            # One torch thread per CPU this process holds: more threads than cores make OpenMP spin
            # against other trials and runners (measured 10-20x slower SAC updates on 2 busy cores).
            threads = max(1, int(self.num_cpus_for_main_process or 1))
            use_fast_gc_sac(self, updates_per_env_step=self.utd_ratio(), torch_threads=threads)
        from copilot_ray.algorithms.copilot.algorithm import register_traversal_env

        register_traversal_env()
        super().validate()

    def traversal_rules(self) -> TraversalRules:
        """How the agent runs and is rewarded on sub-tasks (validated)."""
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

    def _validate_copilot(self) -> None:
        def bad(key: str, value: Any, fix: str) -> ValueError:
            return ValueError(f"CoPilotConfig: {key}={value!r} is invalid: {fix}")

        def positive_int(key: str, value: Any, upper: int | None = None) -> None:
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise bad(key, value, "use an integer >= 1")
            if upper is not None and value > upper:
                raise bad(key, value, f"use an integer <= {upper}")

        # 2^K + 1 sub-goals per tree and 2^(K+1) - 1 sub-tasks per traversal: K = 10 already means
        # 2047 sub-tasks per task; deeper trees are a typo, not an experiment.
        if (
            isinstance(self.tree_depth, bool)
            or not isinstance(self.tree_depth, int)
            or not 0 <= self.tree_depth <= 10
        ):
            raise bad("tree_depth", self.tree_depth, "use an integer in [0, 10] (0: no planner, plain SAC)")
        positive_int("repetitions", self.repetitions)
        positive_int("tau_max", self.tau_max)
        try:
            self.traversal_rules()  # validates the traversal's own knobs
        except ValueError as err:
            raise ValueError(f"CoPilotConfig: {err}") from None
        for key, allowed in (
            ("failed_subtask_cost", FAILED_SUBTASK_COSTS),
            ("traversal_tree", TRAVERSAL_TREES),
            ("eval_action", EVAL_ACTIONS),
        ):
            if getattr(self, key) not in allowed:
                raise bad(key, getattr(self, key), f"use one of {list(allowed)}")
        if (
            isinstance(self.planner_warm_start, bool)
            or not isinstance(self.planner_warm_start, int)
            or self.planner_warm_start < 0
        ):
            raise bad("planner_warm_start", self.planner_warm_start, "use an integer >= 0 (planner phases)")
        positive_int("task_batch_size", self.task_batch_size)
        positive_int("planner_task_batch_size", self.planner_task_batch_size)
        positive_int("subtasks_per_sample", self.subtasks_per_sample)
        positive_int("eval_num_tasks", self.eval_num_tasks)
        if not isinstance(self.eval_interval, int) or self.eval_interval < 0:
            raise bad("eval_interval", self.eval_interval, "use an integer >= 0 (0 disables evaluation)")
        if not isinstance(self.eval_tree_tasks, int) or self.eval_tree_tasks < 0:
            raise bad("eval_tree_tasks", self.eval_tree_tasks, "use an integer >= 0")
        if self.collision_penalty is not None and not (
            isinstance(self.collision_penalty, int | float)
            and not isinstance(self.collision_penalty, bool)
            and self.collision_penalty >= 0
        ):
            raise bad("collision_penalty", self.collision_penalty, "use a number >= 0 (paper: 10), or None")
        if self.collision_cost not in COLLISION_COSTS:
            raise bad("collision_cost", self.collision_cost, f"use one of {list(COLLISION_COSTS)}")
        for key in ("updates_per_env_step", "training_intensity"):
            value = getattr(self, key)
            if value is not None and not (
                isinstance(value, int | float) and not isinstance(value, bool) and value > 0
            ):
                raise bad(key, value, "use a number > 0 (or None)")
        if self.updates_per_env_step is not None and self.training_intensity is not None:
            raise bad(
                "training_intensity",
                self.training_intensity,
                f"updates_per_env_step={self.updates_per_env_step!r} is set too; both set the "
                "update-to-data ratio (training_intensity = updates_per_env_step * train batch size), "
                "set one",
            )
        try:
            AlphaSchedule.from_dict(self.alpha_schedule)
        except (ValueError, TypeError) as err:
            raise bad("alpha_schedule", self.alpha_schedule, str(err)) from err
        for name, given, known in (
            ("planner", self.planner, DEFAULT_PLANNER),
            ("cost_model", self.cost_model, DEFAULT_COST_MODEL),
        ):
            unknown = sorted(set(given) - set(known))
            if unknown:
                raise bad(f"{name}.{unknown[0]}", given[unknown[0]], f"known keys are {sorted(known)}")
        for key in ("std", "lr", "clip"):
            if not self.planner[key] > 0:
                raise bad(f"planner.{key}", self.planner[key], "use a number > 0")
        if self.planner["noise"] not in NOISE_MODES:
            raise bad("planner.noise", self.planner["noise"], f"use one of {list(NOISE_MODES)}")
        if not 0 < self.planner["clip"] < 1:
            raise bad("planner.clip", self.planner["clip"], "use a number in (0, 1) (PPO's clip range)")
        positive_int("planner.std_anneal_phases", self.planner["std_anneal_phases"])
        for key in ("max_grad_norm", "target_kl", "std_final", "max_kl"):
            value = self.planner[key]
            if value is not None and not (
                isinstance(value, int | float) and not isinstance(value, bool) and value > 0
            ):
                raise bad(f"planner.{key}", value, "use a number > 0, or None (off)")
        positive_int("planner.num_samples", self.planner["num_samples"])
        positive_int("planner.epochs", self.planner["epochs"])
        positive_int("cost_model.capacity", self.cost_model["capacity"])
        positive_int("cost_model.fit_steps", self.cost_model["fit_steps"])
        positive_int("cost_model.batch_size", self.cost_model["batch_size"])
        if not isinstance(self.cost_model["init_euclidean"], int) or self.cost_model["init_euclidean"] < 0:
            raise bad("cost_model.init_euclidean", self.cost_model["init_euclidean"], "use an integer >= 0")
        if self.num_envs_per_env_runner != 1:
            raise bad(
                "num_envs_per_env_runner",
                self.num_envs_per_env_runner,
                "CO-PILOT traverses one sub-task queue per runner; use 1 and scale with num_env_runners",
            )
        if self.env is None:
            raise bad("env", None, 'call .environment("maze-point", env_config={...})')
