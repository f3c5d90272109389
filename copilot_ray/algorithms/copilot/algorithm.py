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
`copilot_ray/algorithms/sac/settings.py`). CO-PILOT is the agent (`GoalSAC.training_step`) with its
curriculum (`copilot_ray.planning.curriculum.CoPilotCurriculum`, built by `CoPilotConfig.make_curriculum`):

    (first call only) planner_warm_start planner phases on the Euclidean + collision cost, no env steps
    tasks <- planner_task_batch_size (s0, g) pairs from the train set; the agent traverses the first
             task_batch_size of them
    for repetition in 1..b:
        planner phase   top-down construction (Alg. 1): update pi_p on J^k, sample layer k, k = 1..K
        agent phase     bottom-up traversal (Alg. 2) on the env runners, SAC updates in between
        cost model      D_tau += (start, end, steps) of every sub-task; refit tau_hat
        alpha           the schedule advances one episode
    every evaluation: success on validation and test tasks (planned and direct), paths, trees

With `eval_every_env_steps`, an iteration ends at the repetition that passes an evaluation point and the
next one takes up the same batch, so CO-PILOT is evaluated on the cadence of the short-iteration baselines.

Besides the paper's metrics, `copilot/diag/...` says why a run does or does not learn
(`copilot_ray.planning.plan_diagnostics`).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any, ClassVar

from ray.rllib.utils.annotations import override

from copilot_ray.algorithms.copilot.settings import (
    PRESETS,
    SETTINGS,
    alpha_schedule_from,
    combination_problems,
)
from copilot_ray.algorithms.sac.algorithm import GoalSAC, GoalSACConfig
from copilot_ray.planning import AlphaSchedule
from copilot_ray.planning.curriculum import CoPilotCurriculum
from copilot_ray.settings import Setting, keyword_arguments


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
            # Kept as its full mapping, whatever form it came in (AlphaSchedule.from_dict: a preset name,
            # a mapping, a schedule); a value that is none of them is kept as given: validate() names it.
            try:
                settings["alpha_schedule"] = AlphaSchedule.from_dict(settings["alpha_schedule"]).to_dict()
            except (ValueError, TypeError):
                pass
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

    def make_curriculum(
        self, env, train_tasks, probe_starts, reachable_length, rng, seed
    ) -> CoPilotCurriculum:
        """CO-PILOT's planner side: pi_p, its warm start, tau_hat and D_tau, the alpha clock."""
        settings = {
            key: getattr(self, key)
            for key in (
                "tree_depth",
                "repetitions",
                "task_batch_size",
                "planner_task_batch_size",
                "planner_warm_start",
                "planner_frozen",
                "traversal_tree",
                "failed_subtask_cost",
                "collision_cost",
                "alpha_schedule",
                "planner",
                "cost_model",
            )
        }
        settings["collision_penalty"] = self.collision_penalty_value()
        return CoPilotCurriculum(env, settings, train_tasks, probe_starts, reachable_length, rng, seed)

    def collision_penalty_value(self) -> float:
        """`collision_penalty`, or its default for `collision_cost` (10 per segment, 100 per length)."""
        if self.collision_penalty is not None:
            return float(self.collision_penalty)
        return 100.0 if self.collision_cost == "length" else 10.0


class CoPilot(GoalSAC):
    """CO-PILOT: a sub-goal planner pi_p and the goal-conditioned SAC agent trained together.

    It is `GoalSAC` (the env runners sampling `TraversalEnv`, where one episode is one sub-task; the fast
    goal-conditioned SAC learner; evaluation; checkpoints) with CO-PILOT's curriculum
    (`copilot_ray.planning.curriculum.CoPilotCurriculum`, from `CoPilotConfig.make_curriculum`): the
    planner phase plans the trees the agent traverses, and the finished sub-tasks feed the time-cost
    model and advance the alpha schedule. The curriculum's state is checkpointed under "copilot".
    Configure it with `CoPilotConfig` (`.copilot(...)`).
    """

    @classmethod
    @override(GoalSAC)
    def get_default_config(cls):
        """A fresh `CoPilotConfig`."""
        return CoPilotConfig()
