"""Tiny learning checks: open 2-D reach-the-goal, SAC trained through a real env runner.

The env runner samples episodes, the agent updater CO-PILOT uses (`FastLearnerUpdater`: flat buffer + GC-SAC
learner; `StockLearnerUpdater`: RLlib's prioritised episode buffer + stock SAC module and learner) stores
them and trains, and the runner gets the learner's weights back: the same calls CO-PILOT's
training_step makes.

The suite trains the fast path only, one seed, 7k env steps (about 25 s of one core). The slow
comparison with RLlib's stock path (about 4 min per seed) is `benchmarks/learning_parity.py`; it
imports `ReachGoal2D`, `train` and `success_rate` from this module so that both measure the same thing.
"""

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from copilot_ray.algorithms.gc_sac import GradientStepSchedule, use_fast_learner
from copilot_ray.algorithms.sac.agent_updates import FastLearnerUpdater, StockLearnerUpdater


class ReachGoal2D(gym.Env):
    """Point in [0, 1]^2, obs = (position, goal), step = 0.1 * action, success within 0.1 of the goal.

    Episodes are cut after `max_steps` (50) so that training sees many goals, not a few long walks.
    """

    def __init__(self, config=None):
        self.observation_space = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.max_steps = int((config or {}).get("max_steps", 50))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos, self.goal = self.np_random.uniform(0.0, 1.0, (2, 2))
        self.steps = 0
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.pos, self.goal]).astype(np.float32)

    def step(self, action):
        self.pos = np.clip(self.pos + 0.1 * np.clip(action, -1, 1), 0.0, 1.0)
        self.steps += 1
        success = bool(np.linalg.norm(self.pos - self.goal) < 0.1)
        truncated = not success and self.steps >= self.max_steps
        return self._obs(), 0.0 if success else -1.0, success, truncated, {"success": success}


def success_rate(module, episodes=50, seed=123):
    """Share of `episodes` fixed test episodes (20 steps each) the deterministic policy of `module` solves."""
    env = gym.wrappers.TimeLimit(ReachGoal2D(), max_episode_steps=20)
    wins = 0
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        done = False
        while not done:
            with torch.no_grad():
                logits = module.forward_inference({"obs": torch.as_tensor(obs)[None]})["action_dist_inputs"]
            action = torch.tanh(logits.chunk(2, -1)[0])[0].numpy()  # deterministic: squashed mean
            obs, _, term, trunc, info = env.step(action)
            done = term or trunc
        wins += int(info["success"])
    return wins / episodes


def train(fast: bool, env_steps: int, seed: int = 0, torch_threads: int = 1):
    """Train one path for `env_steps` env steps; returns (learner module, env runner module, updater).

    `env_steps=0` returns the untrained modules. The fast learner sets torch to `torch_threads` threads
    (process-wide); the stock learner leaves torch's thread count as it finds it.
    """
    config = (
        SACConfig()
        .environment(ReachGoal2D)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1, rollout_fragment_length=1)
        .training(train_batch_size_per_learner=64, actor_lr=1e-3, critic_lr=1e-3, alpha_lr=1e-3, gamma=0.95)
        .debugging(seed=seed)
    )
    config.rl_module(model_config={"fcnet_hiddens": [64, 64], "fcnet_activation": "relu"})
    if fast:
        use_fast_learner(config, hidden=(64, 64), torch_threads=torch_threads, updates_per_env_step=1.0)
    runner = SingleAgentEnvRunner(config=config)
    learner_group = config.build_learner_group(env=runner.env)
    updater = (
        FastLearnerUpdater(config, learner_group) if fast else StockLearnerUpdater(config, learner_group)
    )
    schedule = GradientStepSchedule(1.0, learning_starts=500)
    sampled = 0
    while sampled < env_steps:
        # No `random_actions` warm-up: RLlib's episode buffer cannot join a random-action chunk (no
        # action logp) to a policy chunk of the same episode. The untrained policy is near-uniform.
        episodes = runner.sample(num_timesteps=50)
        updater.add(episodes)
        new = sum(len(e) for e in episodes)
        sampled += new
        n = schedule.on_env_steps(new)
        if n:
            updater.update(n, {NUM_ENV_STEPS_SAMPLED_LIFETIME: sampled})
            # Weight sync learner -> env runner (what `env_runner_group.sync_weights` does).
            state = learner_group.get_state(components="learner/rl_module", inference_only=True)["learner"]
            runner.set_state({COMPONENT_RL_MODULE: state[COMPONENT_RL_MODULE]})
    module = learner_group._learner.module[DEFAULT_MODULE_ID]
    return module, runner.module, updater


def test_env_runner_to_buffer_to_learner_to_env_runner_round_trip():
    learner_module, runner_module, updater = train(fast=True, env_steps=700)
    buffer = updater.buffer
    assert len(buffer) >= 700 and buffer.transitions()["terminateds"].any()
    learned = learner_module.state_dict()
    for name, value in runner_module.state_dict().items():  # inference-only: the actor
        torch.testing.assert_close(value, learned[name])


def test_fast_path_learns_to_reach_goals():
    """Fast path, seed 0, 7k env steps. Trial runs (seeds 0-4): the untrained policy solves 0.12-0.16 of
    the test episodes and still 0.10-0.12 after 3k steps; at 6k steps 0.50-1.00, at 7k 0.88-1.00 (seed
    0: 1.00), at 8k 1.00 (1-4). A policy that does not learn stays near its untrained score, far below 0.5."""
    untrained = success_rate(train(fast=True, env_steps=0)[0])
    module, runner_module, _ = train(fast=True, env_steps=7_000)
    rate = success_rate(module)
    assert success_rate(runner_module) == rate  # the env runner got the trained weights
    assert untrained <= 0.3, untrained  # the task is not solved without training
    assert rate >= 0.5 and rate >= untrained + 0.3, (untrained, rate)
