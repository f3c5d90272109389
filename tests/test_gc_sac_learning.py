"""Tiny learning check: open 2-D reach-the-goal, fast GC-SAC driven through a real RLlib env runner.

The env runner samples episodes, `FlatTransitionBuffer.add_episodes` stores them, `update_from_buffer`
trains, and the runner gets the learner's weights back: the same calls CO-PILOT's training_step makes.
"""

import time

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

from copilot_ray.algorithms.gc_sac import (
    FlatTransitionBuffer,
    GradientStepSchedule,
    update_from_buffer,
    use_fast_gc_sac,
)


class ReachGoal2D(gym.Env):
    """Point in [0, 1]^2, obs = (position, goal), step = 0.1 * action, success within 0.1 of the goal."""

    def __init__(self, config=None):
        self.observation_space = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos, self.goal = self.np_random.uniform(0.0, 1.0, (2, 2))
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self.pos, self.goal]).astype(np.float32)

    def step(self, action):
        self.pos = np.clip(self.pos + 0.1 * np.clip(action, -1, 1), 0.0, 1.0)
        success = bool(np.linalg.norm(self.pos - self.goal) < 0.1)
        return self._obs(), 0.0 if success else -1.0, success, False, {"success": success}


def _success_rate(module, episodes=50, seed=123):
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


def _train(fast: bool, env_steps: int, seed: int = 0):
    config = (
        SACConfig()
        .environment(ReachGoal2D)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=1, rollout_fragment_length=1)
        .training(train_batch_size_per_learner=64, actor_lr=1e-3, critic_lr=1e-3, alpha_lr=1e-3, gamma=0.95)
        .debugging(seed=seed)
    )
    config.rl_module(model_config={"fcnet_hiddens": [64, 64], "fcnet_activation": "relu"})
    if fast:
        use_fast_gc_sac(config, hidden=(64, 64), torch_threads=1, updates_per_env_step=1.0)
    runner = SingleAgentEnvRunner(config=config)
    learner_group = config.build_learner_group(env=runner.env)
    buffer = FlatTransitionBuffer(capacity=100_000)
    schedule = GradientStepSchedule(1.0, learning_starts=500)
    rng = np.random.default_rng(seed)
    sampled = 0
    while sampled < env_steps:
        episodes = runner.sample(num_timesteps=50, random_actions=sampled < 500)
        buffer.add_episodes(episodes)
        new = sum(len(e) for e in episodes)
        sampled += new
        n = schedule.on_env_steps(new)
        if n:
            # The stock learner moves its targets once per call: one gradient step per call for it.
            update_from_buffer(
                learner_group,
                buffer,
                n,
                64,
                rng,
                sampled,
                with_weights_and_n_step=not fast,
                steps_per_call=16 if fast else 1,
            )
            # Weight sync learner -> env runner (what `env_runner_group.sync_weights` does).
            state = learner_group.get_state(components="learner/rl_module", inference_only=True)["learner"]
            runner.set_state({COMPONENT_RL_MODULE: state[COMPONENT_RL_MODULE]})
    module = learner_group._learner.module[DEFAULT_MODULE_ID]
    return module, runner.module, buffer


def test_env_runner_to_buffer_to_learner_to_env_runner_round_trip():
    learner_module, runner_module, buffer = _train(fast=True, env_steps=700)
    assert len(buffer) >= 700 and buffer.transitions()["terminateds"].any()
    learned = learner_module.state_dict()
    for name, value in runner_module.state_dict().items():  # inference-only: the actor
        torch.testing.assert_close(value, learned[name])


def test_fast_gc_sac_learns_to_reach_goals():
    t0 = time.perf_counter()
    module, runner_module, _ = _train(fast=True, env_steps=8000)
    rate = _success_rate(module)
    print(f"fast GC-SAC: success {rate:.2f} after 8000 env steps in {time.perf_counter() - t0:.1f} s")
    assert rate >= 0.7  # random actions: about 0.1; 1.0 seen in a trial run
    assert _success_rate(runner_module) >= 0.7  # the env runner got the trained weights
