"""Tiny learning checks: open 2-D reach-the-goal, SAC trained through a real env runner.

The env runner samples episodes, the agent updater CO-PILOT uses (`FastLearnerUpdater`: flat buffer + GC-SAC
learner; `StockLearnerUpdater`: RLlib's prioritised episode buffer + stock SAC module and learner) stores
them and trains, and the runner gets the learner's weights back: the same calls CO-PILOT's
training_step makes.

The suite checks the loop's plumbing and that the fast learner learns a one-step task (seconds); how
fast the loop learns the multi-step reach task, fast path against RLlib's stock path, is a figure of
`benchmarks/learning_parity.py`, which imports `ReachGoal2D`, `train` and `success_rate` from here so
that both measure the same thing.
"""

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import COMPONENT_RL_MODULE, DEFAULT_MODULE_ID
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from copilot_ray.algorithms.gc_sac import (
    FlatTransitionBuffer,
    GradientStepSchedule,
    host_sampler,
    update_from_buffer,
    use_fast_learner,
)
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
    if fast:
        updater = FastLearnerUpdater(config, learner_group, FlatTransitionBuffer(100_000, seed=seed))
    else:
        updater = StockLearnerUpdater(config, learner_group)
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


def _steer_target(obs):
    """The best action of the one-step task below: towards the goal, saturating 1/3 of the width away."""
    return np.clip(3.0 * (obs[:, 2:] - obs[:, :2]), -1.0, 1.0)


def _steer_error(module, seed=99):
    """Mean squared distance of the deterministic action (squashed mean) from the best one, 500 states."""
    obs = np.random.default_rng(seed).uniform(0.0, 1.0, (500, 4)).astype(np.float32)
    with torch.no_grad():
        logits = module.forward_inference({"obs": torch.as_tensor(obs)})["action_dist_inputs"]
    action = torch.tanh(logits.chunk(2, -1)[0]).numpy()
    return float(np.mean(np.sum((action - _steer_target(obs)) ** 2, -1)))


def test_the_fast_learner_finds_the_best_action_of_a_one_step_task():
    """Critic, actor and squashing learn together: from random actions with reward -|a - a*(s)|^2 (every
    transition terminal, so Q must fit the reward), 300 gradient steps bring the greedy action to a*.
    Measured (seeds 0-2): the error falls from 1.22-1.31 to 0.07-0.09 (0.03-0.04 after 600 steps).
    How fast the whole loop learns a multi-step task is `benchmarks/learning_parity.py`'s figure."""
    rng = np.random.default_rng(0)
    obs = rng.uniform(0.0, 1.0, (4096, 4)).astype(np.float32)
    actions = rng.uniform(-1.0, 1.0, (4096, 2)).astype(np.float32)
    buffer = FlatTransitionBuffer(capacity=4096)
    buffer.add(
        {
            "obs": obs,
            "new_obs": obs,
            "actions": actions,
            "rewards": -np.sum((actions - _steer_target(obs)) ** 2, -1),
            "terminateds": np.ones(4096, bool),
        }
    )
    config = SACConfig().environment(observation_space=ReachGoal2D().observation_space).debugging(seed=0)
    config.environment(action_space=ReachGoal2D().action_space)
    config.training(actor_lr=3e-3, critic_lr=3e-3, alpha_lr=3e-3, initial_alpha=0.01)
    use_fast_learner(config, hidden=(64, 64), torch_threads=1)
    learner_group = config.build_learner_group()
    module = learner_group._learner.module[DEFAULT_MODULE_ID]
    untrained = _steer_error(module)
    update_from_buffer(
        learner_group, host_sampler(buffer), num_gradient_steps=300, batch_size=128, timesteps=4096
    )
    trained = _steer_error(module)
    assert untrained > 0.8, untrained  # a fresh policy does not steer
    assert trained < 0.25, (untrained, trained)
