"""Goal-conditioned SAC on whole tasks, with optional hindsight relabelling: `GoalSACConfig` and
`GoalSAC`, the paper's SAC and HER baselines.

    config = GoalSACConfig().environment("maze-point", env_config={"layout": "four-rooms"})
    config.hindsight(n_sampled_goal=4)          # HER; without it: plain SAC
    algo = config.build_algo()

This is CO-PILOT with tree depth 0 (no planner, no time-cost model), which is what the paper's SAC
baseline is: every part that touches the agent (env runners on the traversal env, the fast
goal-conditioned SAC learner, replay, checkpoints, evaluation on the same test tasks) is CO-PILOT's,
so a comparison differs only in the planner. One iteration runs one episode of at most `tau_max` steps
on each of `task_batch_size` training tasks, with `utd_ratio()` SAC updates per new env step.

HER is a replay buffer, as in Stable-Baselines3: `gc_sac.HindsightReplayBuffer` relabels goals when
a batch is sampled and recomputes rewards with the goal env's `compute_reward` / `compute_terminated`
under the same `TraversalRules.reward` the env runners use, so a relabelled transition is rewarded
exactly as a real one reaching that goal would be.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import numpy as np
from ray.rllib.utils.annotations import override

from copilot_ray.algorithms.copilot.agent_updates import FastLearnerUpdater, replay_capacity
from copilot_ray.algorithms.copilot.algorithm import CoPilot, CoPilotConfig
from copilot_ray.algorithms.gc_sac import GoalLayout, HindsightReplayBuffer
from copilot_ray.algorithms.sac import settings as sac_settings
from copilot_ray.registry import RunContext

_HINDSIGHT_DEFAULTS = {s.field: s.default for s in sac_settings.HINDSIGHT}


class GoalSACConfig(CoPilotConfig):
    """CO-PILOT's config at tree depth 0 with the baselines' defaults (settings.py) and `.hindsight()`."""

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or GoalSAC)
        training = {}
        for s in sac_settings.AGENT:
            if s.target == "training":
                training[s.key] = s.default
            else:
                setattr(self, s.key, copy.deepcopy(s.default))
        self.training(**training)
        # No planner: one sub-task per task, no warm start, no time-cost model to seed or trees to draw.
        self.tree_depth = 0
        self.repetitions = 1
        self.planner_warm_start = 0
        self.eval_tree_tasks = 0
        self.cost_model = {**self.cost_model, "init_euclidean": 0}
        # n_sampled_goal 0: plain SAC on CO-PILOT's flat buffer (no relabelling, no goal bookkeeping).
        self.her: dict[str, Any] = {"n_sampled_goal": 0, "goal_selection": "future"}

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: RunContext) -> GoalSACConfig:
        """A config from flat setting values (`her.*` go to `.hindsight`, the rest as CO-PILOT's)."""
        her = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("her.")}
        config = super().from_settings({k: v for k, v in values.items() if not k.startswith("her.")}, run)
        if her:
            config.hindsight(**{**_HINDSIGHT_DEFAULTS, **her})
        return config

    def hindsight(self, **settings: Any) -> GoalSACConfig:
        """HER's settings: n_sampled_goal (>= 1 relabels; SB3's default 4), goal_selection ("future",
        "final", "episode"). Checked by validate()."""
        unknown = sorted(set(settings) - set(_HINDSIGHT_DEFAULTS))
        if unknown:
            raise ValueError(
                f"GoalSACConfig.hindsight: unknown setting {unknown[0]!r}; known: {sorted(_HINDSIGHT_DEFAULTS)}"
            )
        self.her = {**self.her, **settings}
        return self

    @override(CoPilotConfig)
    def validate(self) -> None:
        if self.tree_depth != 0:
            raise ValueError(
                f"{type(self).__name__}: tree_depth={self.tree_depth!r} is invalid: the agent-only baselines "
                "have no planner (use algorithm copilot for K > 0)"
            )
        n = self.her.get("n_sampled_goal")
        if n != 0:
            for s in sac_settings.HINDSIGHT:
                if (why := s.problem(self.her.get(s.field))) is not None:
                    raise ValueError(
                        f"{type(self).__name__}: {s.key}={self.her.get(s.field)!r} is invalid: {why}"
                    )
        if self.uses_hindsight_buffer() and not self.fast_learner:
            raise ValueError(
                f"{type(self).__name__}: fast_learner=False is invalid with hindsight relabelling: "
                "the relabelling buffer feeds the fast learner"
            )
        super().validate()

    def uses_hindsight_buffer(self) -> bool:
        """Whether the agent's replay is the hindsight buffer (HER, or an algorithm that reads states)."""
        return self.her.get("n_sampled_goal", 0) > 0


class GoalSAC(CoPilot):
    """Goal-conditioned SAC on whole training tasks; HER when `her["n_sampled_goal"]` > 0 (module
    docstring). Logs `copilot/eval/success` = success on the test tasks (the agent alone, `tau_max`
    steps), as `success_direct` and `success_planned` (equal here: there is no plan)."""

    @classmethod
    @override(CoPilot)
    def get_default_config(cls):
        return GoalSACConfig()

    @override(CoPilot)
    def _make_agent_updater(self):
        cfg = self.config
        if not cfg.uses_hindsight_buffer():
            return super()._make_agent_updater()
        buffer = HindsightReplayBuffer(
            replay_capacity(cfg),
            self.goal_layout(),
            self.relabelled_reward,
            n_sampled_goal=cfg.her["n_sampled_goal"],
            goal_selection=cfg.her["goal_selection"],
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
        env = self.goal_env.unwrapped
        reached = env.compute_terminated(next_achieved, goals, None)
        return self.rules.reward(env.compute_reward(next_achieved, goals, None), reached, collisions, layer=0)


class HERConfig(GoalSACConfig):
    """`GoalSACConfig` with hindsight relabelling on at SB3's defaults (`algorithm: her`)."""

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class)
        self.her = dict(_HINDSIGHT_DEFAULTS)
