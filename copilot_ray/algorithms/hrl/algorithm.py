"""`HRL`: the two-level hierarchy's training loop, evaluation and state, without Tune (trial.py wraps it).

One `train()` is one iteration: batches of `task_batch_size` training episodes (random training tasks,
run side by side) until `env_steps_per_iteration` env steps, each batch followed by the low level's
`updates_per_env_step` x new env steps and the high level's `updates_per_transition` x new high-level
transitions SAC gradient steps; then, every `eval_interval` iterations (or `eval_every_env_steps`), an
evaluation on the first `eval_num_tasks` validation tasks (the headline action) and test tasks with
`tau_max` steps each, deterministic and sampled actions (both levels).
Before `num_steps_sampled_before_learning_starts` env steps both levels act uniformly at random.
"""

from __future__ import annotations

import functools
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from copilot_ray import keys
from copilot_ray.algorithms.gc_sac import (
    FlatTransitionBuffer,
    GradientStepSchedule,
    host_sampler,
    update_from_buffer,
)
from copilot_ray.algorithms.hrl import settings as S
from copilot_ray.algorithms.hrl.buffer import SegmentReplayBuffer
from copilot_ray.algorithms.hrl.config import HRLConfig
from copilot_ray.algorithms.hrl.hierarchy import SubgoalBox, choose_candidates, correction_candidates
from copilot_ray.algorithms.hrl.levels import Actor, build_learner_group, learner_stats
from copilot_ray.algorithms.hrl.rollout import Episode, run_episodes
from copilot_ray.algorithms.hrl.transitions import high_level_rows, low_level_rows, subgoals_reached
from copilot_ray.envs import make
from copilot_ray.envs.goal_observation import flat_observation, flat_observation_space
from copilot_ray.evaluation import EVAL_SPLITS, AgentEvaluation

# The evaluation's figures per action mode (the agent alone: what it follows is its own high level).
_EVAL_KEYS = (keys.SUCCESS_DIRECT, keys.REACHED_DIRECT, keys.SUCCESS_PLANNED, keys.REACHED_PLANNED)


class HRL:
    """HIRO-style two-level goal-conditioned SAC (see the package docstring)."""

    def __init__(self, cfg: HRLConfig):
        self.cfg = cfg
        self.envs = [make(cfg.env_id, **dict(cfg.env_config)) for _ in range(cfg.task_batch_size)]
        goal_env = self.envs[0]
        maze = goal_env.unwrapped
        self.compute_reward, self.compute_terminated = maze.compute_reward, maze.compute_terminated
        self.box = SubgoalBox.from_goal_space(
            maze.goal_space.low, maze.goal_space.high, cfg.hrl_subgoal_range
        )
        self.with_delta = cfg.agent_input == "state_goal_delta"
        flat_space = flat_observation_space(goal_env, self.with_delta)
        self.action_dim = int(goal_env.action_space.shape[0])
        self.goal_dim = int(maze.goal_space.shape[0])
        high_space = gym.spaces.Box(-1.0, 1.0, (self.goal_dim,), np.float32)
        self.low_group = build_learner_group(cfg, "low", flat_space, goal_env.action_space)
        self.high_group = build_learner_group(cfg, "high", flat_space, high_space)
        torch.manual_seed(cfg.seed)  # the learners' own sampling, after RLlib seeded their nets
        self.generator = torch.Generator().manual_seed(cfg.seed)  # exploration while training
        self.low, self.high = Actor(self.low_group), Actor(self.high_group)
        self.rng = np.random.default_rng([cfg.seed, 0])  # training tasks, random warm-up actions
        self.high_rng = np.random.default_rng([cfg.seed, 2])  # high-level replay sampling + candidates
        self.low_buffer = FlatTransitionBuffer(cfg.replay_capacity, seed=cfg.seed)  # samples its own stream
        corrector = self.correct if cfg.hrl_off_policy_correction else None
        self.high_buffer = SegmentReplayBuffer(max(1, cfg.replay_capacity // cfg.hrl_c), corrector)
        self.low_schedule = GradientStepSchedule(
            cfg.low["updates_per_env_step"], cfg.num_steps_sampled_before_learning_starts
        )
        self.high_schedule = GradientStepSchedule(cfg.high["updates_per_transition"])
        self.train_starts, self.train_goals = maze.tasks("train")
        # Validation tasks for searchers and probes, test tasks for reports: both at every evaluation,
        # measured as every agent-based method is (copilot_ray.evaluation.AgentEvaluation).
        reward = float(getattr(maze, "goal_reward", 1.0)) * cfg.reward_scale  # R, for the return
        self.evaluation = AgentEvaluation(
            maze, cfg.eval_num_tasks, cfg.eval_action, cfg.eval_interval, cfg.eval_every_env_steps, reward
        )
        self.eval_envs: list | None = None
        self.env_steps = 0
        self.iteration = 0
        self.last_eval: dict[str, float] = {}

    # ------------------------------------------------------------------ the pieces
    def compose(self, observation: np.ndarray, goal: np.ndarray, achieved: np.ndarray) -> np.ndarray:
        """A level's flat input: concat(observation, goal[, goal - achieved]) (`agent_input`)."""
        return flat_observation(observation, goal, achieved if self.with_delta else None)

    def correct(
        self, batch: dict[str, np.ndarray], rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """HIRO's off-policy correction of sampled high-level actions (SegmentReplayBuffer's corrector)."""
        stored = self.box.offset(batch["actions"])
        cands = correction_candidates(
            stored, batch["start"], batch["end"], self.box, self.cfg.hrl_num_candidates, rng
        )
        best = choose_candidates(
            cands,
            batch["start"],
            batch["seg_obs"],
            batch["seg_achieved"],
            batch["seg_actions"],
            batch["seg_mask"],
            self.low.log_prob,
            self.compose,
        )
        kept = best == 0
        relabelled = self.box.action(cands[np.arange(len(best)), best])
        return np.where(kept[:, None], batch["actions"], relabelled), kept

    def _random(self, dim: int):
        return lambda x: self.rng.uniform(-1.0, 1.0, (len(x), dim)).astype(np.float32)

    def _episodes(self, envs, starts, goals, high, low) -> list[Episode]:
        cfg = self.cfg
        return run_episodes(envs, starts, goals, high, low, self.box, cfg.hrl_c, cfg.tau_max, self.compose)

    # ------------------------------------------------------------------ training
    def train(self) -> dict[str, float]:
        """One iteration; returns flat metrics (the last evaluation's figures when this one has none)."""
        cfg = self.cfg
        start_steps, returns, reached, stats = self.env_steps, [], [], {}
        kept_before, corrected_before = self.high_buffer.num_kept, self.high_buffer.num_corrected
        while self.env_steps - start_steps < cfg.env_steps_per_iteration:
            idx = self.rng.integers(len(self.train_starts), size=cfg.task_batch_size)
            if self.env_steps < cfg.num_steps_sampled_before_learning_starts:
                high, low = self._random(self.goal_dim), self._random(self.action_dim)
            else:
                high = lambda x: self.high.act(x, self.generator)  # noqa: E731
                low = lambda x: self.low.act(x, self.generator)  # noqa: E731
            episodes = self._episodes(self.envs, self.train_starts[idx], self.train_goals[idx], high, low)
            rows = low_level_rows(
                episodes,
                cfg.hrl_c,
                self.compose,
                cfg.hrl_low_reward,
                self.compute_reward,
                self.compute_terminated,
            )
            self.low_buffer.add(rows)
            added = self.high_buffer.add(high_level_rows(episodes, cfg.hrl_c, self.compose, cfg.reward_scale))
            n = sum(len(ep) for ep in episodes)
            self.env_steps += n
            returns += [cfg.reward_scale * float(ep.rewards.sum()) for ep in episodes]
            reached.append(subgoals_reached(episodes, cfg.hrl_c, self.compute_terminated))
            learning = self.env_steps >= cfg.num_steps_sampled_before_learning_starts
            high_sample = functools.partial(self.high_buffer.sample, rng=self.high_rng)
            for level, group, buffer, sample, steps in (
                (
                    "low",
                    self.low_group,
                    self.low_buffer,
                    host_sampler(self.low_buffer),
                    self.low_schedule.on_env_steps(n),
                ),
                (
                    "high",
                    self.high_group,
                    self.high_buffer,
                    high_sample,
                    self.high_schedule.on_env_steps(added if learning else 0),
                ),
            ):
                settings = getattr(cfg, level)
                steps = steps if len(buffer) else 0
                results = update_from_buffer(
                    group, sample, steps, settings["train_batch_size_per_learner"], self.env_steps
                )
                stats.update({f"{keys.HRL_PREFIX}{level}/{k}": v for k, v in learner_stats(results).items()})
        self.iteration += 1
        corrected = self.high_buffer.num_corrected - corrected_before
        metrics = {
            keys.ENV_STEPS: self.env_steps,
            S.EPISODE_RETURN_MEAN: float(np.mean(returns)),
            S.SUBGOAL_REACHED: float(np.concatenate(reached).mean()),
            **stats,
        }
        if corrected:
            metrics[S.CORRECTION_KEPT] = (self.high_buffer.num_kept - kept_before) / corrected
        metrics.update(dict.fromkeys(keys.PRIVILEGE_COUNTS, 0.0))  # none: its own episodes alone
        fresh = self.evaluation.schedule.due(self.iteration, self.env_steps)
        if fresh:
            self.last_eval = self.evaluate()
        metrics.update(self.last_eval or dict.fromkeys(self._eval_names(), float("nan")))
        metrics[keys.EVAL_FRESH] = 1.0 if fresh else 0.0
        return metrics

    # ------------------------------------------------------------------ evaluation
    def _eval_names(self) -> list[str]:
        per_action = [keys.eval_by_action(k, a) for k in _EVAL_KEYS for a in keys.EVAL_ACTIONS]
        headline = [keys.EVAL_SUCCESS, keys.EVAL_SUCCESS_AUC, keys.EVAL_RETURN, *_EVAL_KEYS]
        return [*headline, *per_action, *keys.validation_metrics(*headline)]

    def evaluate(self) -> dict[str, float]:
        """The validation tasks (the headline action's figures, for searchers), then the test tasks."""
        out: dict[str, float] = {}
        for split in EVAL_SPLITS:
            out.update(self.evaluation.figures(split, self._rollouts(split), self.env_steps))
        return out

    def _rollouts(self, split: str) -> dict[str, dict[str, float]]:
        """Both levels on one task set, lockstep, in the action modes `AgentEvaluation` asks for
        (deterministic: tanh of the means; sampled: from its own seeded stream, so that an evaluation
        does not move training's randomness). Success: the goal reached with no collision."""
        cfg = self.cfg
        starts, goals = self.evaluation.tasks[split]
        if self.eval_envs is None:
            self.eval_envs = [make(cfg.env_id, **dict(cfg.env_config)) for _ in range(len(starts))]
        by_action = {}
        for action, seed in self.evaluation.action_seeds(split, cfg.seed, self.iteration).items():
            gen = None if seed is None else torch.Generator().manual_seed(seed)
            episodes = self._episodes(
                self.eval_envs[: len(starts)],
                starts,
                goals,
                lambda x, g=gen: self.high.act(x, g),
                lambda x, g=gen: self.low.act(x, g),
            )
            by_action[action] = {
                keys.eval_leaf(keys.SUCCESS_DIRECT): float(np.mean([ep.success for ep in episodes])),
                keys.eval_leaf(keys.REACHED_DIRECT): float(np.mean([ep.terminated for ep in episodes])),
            }
        return by_action

    # ------------------------------------------------------------------ state
    def get_state(self) -> dict[str, Any]:
        """Everything `set_state` needs to continue exactly: both learners (nets, optimizers, alpha),
        both replays, the update schedules, every random stream and the counters."""
        return {
            "low_group": self.low_group.get_state(),
            "high_group": self.high_group.get_state(),
            "low_buffer": self.low_buffer.get_state(),
            "high_buffer": self.high_buffer.get_state(),
            "low_schedule": self.low_schedule.get_state(),
            "high_schedule": self.high_schedule.get_state(),
            "rngs": [r.bit_generator.state for r in (self.rng, self.high_rng)],
            "generator": self.generator.get_state(),
            "torch_rng": torch.get_rng_state(),
            "env_steps": self.env_steps,
            "iteration": self.iteration,
            "last_eval": dict(self.last_eval),
            **self.evaluation.get_state(),  # its schedule and success curves
        }

    def set_state(self, state: dict[str, Any]) -> None:
        self.low_group.set_state(state["low_group"])
        self.high_group.set_state(state["high_group"])
        self.low_buffer.set_state(state["low_buffer"])
        self.high_buffer.set_state(state["high_buffer"])
        self.low_schedule.set_state(state["low_schedule"])
        self.high_schedule.set_state(state["high_schedule"])
        for r, s in zip((self.rng, self.high_rng), state["rngs"], strict=True):
            r.bit_generator.state = s
        self.generator.set_state(state["generator"])
        torch.set_rng_state(state["torch_rng"])
        self.env_steps, self.iteration = int(state["env_steps"]), int(state["iteration"])
        self.last_eval = dict(state["last_eval"])
        self.evaluation.set_state(state)

    def stop(self) -> None:
        for env in self.envs + (self.eval_envs or []):
            env.close()
        for group in (self.low_group, self.high_group):
            group.shutdown()
