"""RLlib's PPO on the flattened goal env: `GoalTaskEnv`, `GoalPPOConfig` and `GoalPPO`.

    config = GoalPPOConfig().environment("maze-point", env_config={"layout": "four-rooms"})
    algo = config.build_algo()

The user names the goal-conditioned env; `validate()` swaps in `GoalTaskEnv` (as CO-PILOT swaps in its
traversal env) and keeps the goal env's id and config. `training_step` is RLlib's PPO's; every
`eval_interval` iterations the policy runs on the same test tasks as every other method, with the same
step budget (`tau_max`), and logs `copilot/eval/success` (= `success_direct`).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from ray.rllib.algorithms.ppo import PPO, PPOConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.utils.annotations import override
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.tune.registry import register_env

from copilot_ray import keys
from copilot_ray.algorithms.local_logdir import LocalLogdir
from copilot_ray.algorithms.ppo import settings as ppo_settings
from copilot_ray.algorithms.sac.traversal_env import TraversalRules
from copilot_ray.envs import make
from copilot_ray.envs.goal_observation import flat_observation, flat_observation_space
from copilot_ray.evaluation import EVAL_SPLITS, AgentEvaluation, ModulePolicy, evaluate_copilot
from copilot_ray.registry import RunContext

GOAL_TASK_ENV_ID = "copilot-goal-task"
_TASK_KEYS = [s.key for s in ppo_settings.TASK]
_STATE_KEY = "goal_ppo"
_RULE_KEYS = [k for k in _TASK_KEYS if k in TraversalRules.__dataclass_fields__]


class GoalTaskEnv(gym.Env):
    """One episode = one training task (s0, g) of the goal env, drawn by the goal env's own reset
    (its `task_split`), with a flat observation (`flat_observation`) and at most `tau_max` steps.
    Rewarded as every agent here: `TraversalRules.reward` at layer 0."""

    metadata = {"render_modes": []}

    def __init__(self, config: Mapping[str, Any]):
        self.goal_env = make(config["goal_env"], **dict(config.get("goal_env_config") or {}))
        self.rules = TraversalRules.from_config(config)
        self._with_delta = self.rules.agent_input == "state_goal_delta"
        self.observation_space = flat_observation_space(self.goal_env, self._with_delta)
        self.action_space = self.goal_env.action_space
        self._steps = 0

    def _flat(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        return flat_observation(
            obs["observation"], obs["desired_goal"], obs["achieved_goal"] if self._with_delta else None
        )

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.goal_env.reset(seed=seed, options=options)
        self._steps = 0
        return self._flat(obs), info

    def step(self, action):
        obs, reward, reached, _, info = self.goal_env.step(np.clip(action, -1.0, 1.0))
        self._steps += 1
        reward, terminated = self.rules.reward(
            reward, reached, bool(info.get("collision", False)), dense=float(info.get("dense_reward", 0.0))
        )
        truncated = not terminated and self._steps >= self.rules.tau_max
        return self._flat(obs), float(reward), bool(terminated), bool(truncated), info


def register_goal_task_env() -> None:
    register_env(GOAL_TASK_ENV_ID, GoalTaskEnv)


class GoalPPOConfig(PPOConfig):
    """RLlib's `PPOConfig` plus the task and evaluation settings of settings.py (`.goal_task(...)`)."""

    def __init__(self, algo_class=None):
        super().__init__(algo_class=algo_class or GoalPPO)
        self.goal_env: str | None = None
        self.goal_env_config: dict[str, Any] = {}
        self.num_env_runners = 0  # as every algorithm here: sampling in the run's own process unless asked
        for s in ppo_settings.TASK:
            setattr(self, s.key, copy.deepcopy(s.default))
        self.training(**{s.key: s.default for s in ppo_settings.TRAINING})

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: RunContext) -> GoalPPOConfig:
        training = {k: v for k, v in values.items() if ppo_settings.SETTINGS[k].target == "training"}
        task = {k: v for k, v in values.items() if k in _TASK_KEYS}
        return (
            cls()
            .environment(run.env_id, env_config=dict(run.env_config))
            .env_runners(num_env_runners=run.num_env_runners)
            .resources(num_cpus_for_main_process=run.num_cpus_for_main_process)
            .learners(num_gpus_per_learner=run.num_gpus)  # RLlib places the learner there
            .debugging(seed=run.seed)
            .training(**training)
            .goal_task(**task)
        )

    def goal_task(self, **settings: Any) -> GoalPPOConfig:
        """tau_max, reward_scale, agent_collision, agent_collision_penalty, agent_input, eval_interval,
        eval_num_tasks, eval_action (settings.py)."""
        unknown = sorted(set(settings) - set(_TASK_KEYS))
        if unknown:
            raise ValueError(f"GoalPPOConfig.goal_task: unknown setting {unknown[0]!r}; known: {_TASK_KEYS}")
        for key, value in settings.items():
            setattr(self, key, value)
        return self

    @override(PPOConfig)
    def validate(self) -> None:
        for key in _TASK_KEYS:
            value = getattr(self, key)
            if (why := ppo_settings.SETTINGS[key].problem(value)) is not None:
                raise ValueError(f"GoalPPOConfig: {key}={value!r} is invalid: {why}")
        if self.env is None:
            raise ValueError(
                'GoalPPOConfig: env=None is invalid: call .environment("maze-point", env_config={...})'
            )
        if self.env != GOAL_TASK_ENV_ID:
            self.goal_env = self.env
            self.goal_env_config = copy.deepcopy(dict(self.env_config or {}))
            self.env = GOAL_TASK_ENV_ID
        self.env_config = {
            "goal_env": self.goal_env,
            "goal_env_config": self.goal_env_config,
            **{k: getattr(self, k) for k in _RULE_KEYS},
        }
        register_goal_task_env()
        super().validate()


class GoalPPO(LocalLogdir, PPO):
    """RLlib's PPO plus the common evaluation (module docstring)."""

    @classmethod
    @override(PPO)
    def get_default_config(cls):
        return GoalPPOConfig()

    @override(PPO)
    def setup(self, config) -> None:
        register_goal_task_env()
        super().setup(config)
        cfg = self.config
        self.goal_env = make(cfg.goal_env, **cfg.goal_env_config)
        self.test_starts, self.test_goals = self.goal_env.unwrapped.tasks("test")
        # R: what reaching a task's goal is worth (the goal env's reward x reward_scale).
        reward = float(getattr(self.goal_env.unwrapped, "goal_reward", 1.0)) * cfg.reward_scale
        self.evaluation = AgentEvaluation(
            self.goal_env.unwrapped,
            cfg.eval_num_tasks,
            cfg.eval_action,
            cfg.eval_interval,
            cfg.eval_every_env_steps,
            reward,
        )

    @override(PPO)
    def training_step(self) -> None:
        super().training_step()
        for key in keys.PRIVILEGE_COUNTS:  # none: PPO learns from its own episodes alone
            self.metrics.log_value(keys.metric_path(key), 0, window=1)
        env_steps = int(self.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0))
        if self.evaluation.schedule.due(self.iteration + 1, env_steps):
            for split in EVAL_SPLITS:
                self._evaluate(split, env_steps)

    def _evaluate(self, split: str, env_steps: int) -> None:
        """The agent alone on one task set, through the common protocol (`AgentEvaluation`)."""
        cfg = self.config
        starts, goals = self.evaluation.tasks[split]
        module = self.get_module(DEFAULT_MODULE_ID)
        # PPO's Gaussian is not squashed: its actions are clipped, as GoalTaskEnv clips them.
        policies = {
            action: ModulePolicy(module, squash="clip")
            if seed is None
            else ModulePolicy(module, sampled=True, seed=seed, squash="clip")
            for action, seed in self.evaluation.action_seeds(split, cfg.seed, self.iteration).items()
        }
        result = evaluate_copilot(
            goal_env_id=cfg.goal_env,
            goal_env_config=cfg.goal_env_config,
            policies=policies,
            planner=None,
            starts=starts,
            goals=goals,
            depth=0,
            tau_max=cfg.tau_max,
            with_delta=cfg.agent_input == "state_goal_delta",
        )
        for key, value in self.evaluation.figures(split, result.by_action, env_steps).items():
            self.metrics.log_value(keys.metric_path(key), value, window=1)

    @override(PPO)
    def get_state(self, components=None, *, not_components=None, **kwargs) -> dict[str, Any]:
        """PPO's state plus the evaluation's schedule and success curves."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        state[_STATE_KEY] = self.evaluation.get_state()
        return state

    @override(PPO)
    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)
        own = state.get(_STATE_KEY)
        if own is None:
            return
        self.evaluation.set_state(own)
