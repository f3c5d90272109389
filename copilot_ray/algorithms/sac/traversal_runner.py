"""The traversal's env runner: RLlib's `SingleAgentEnvRunner` with a lean loop for whole sub-tasks.

`GoalSAC` samples the traversal one sub-task at a time (`sample(num_episodes=k)`). RLlib's loop spends
most of an env step around it: the env-to-module and module-to-env connector pipelines (a dozen
pieces, each walking the batch and the episodes), an episode `add_env_step` with its lookback buffers,
three episode callbacks and several timers, per step. `TraversalEnvRunner._sample` does the same
steps without them, for episode sampling:

    obs -> torch [1, d] -> the module's forward_exploration (forward_inference when not exploring),
           in eval mode, set once (RLlib switches modes twice per call)
        -> the module's action distribution: sample (its deterministic twin when not exploring)
        -> unsquash (normalize_actions) or clip (clip_actions) for the env, as RLlib's connector
           computes it -> env.step

and builds each finished sub-task's `SingleAgentEpisode` once, from its lists. These are the calls
RLlib's pipeline makes, in the same order, so for the same weights and torch seed both loops give the
same episodes (`tests/test_traversal_runner.py`). The env is reset at the start of every call and
seeded on the first reset of each, as RLlib does in episode mode. Sampled env steps, episodes and
their returns are logged into the runner's metrics as RLlib logs them; episode callbacks are not
called (nothing here registers any; a config with callbacks keeps RLlib's loop). Everything else (weight
sync, state, metrics, `num_timesteps` sampling, random actions) is `SingleAgentEnvRunner`'s own.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.utils.annotations import override
from ray.rllib.utils.spaces.space_utils import clip_action, unsquash_action


class TraversalEnvRunner(SingleAgentEnvRunner):
    """`SingleAgentEnvRunner` whose episode sampling is one lean loop (module docstring).

    `act_hook(obs, explore) -> action` (default None: the module acts): where a stacked trial's seed
    gets its actions instead, from one batched forward pass for all seeds of the stack
    (`stacked_updates.SeedUpdater.act`)."""

    act_hook = None

    @override(SingleAgentEnvRunner)
    def _sample(
        self,
        *,
        num_timesteps: int | None = None,
        num_episodes: int | None = None,
        explore: bool,
        random_actions: bool = False,
        force_reset: bool = False,
    ) -> list[SingleAgentEpisode]:
        if num_episodes is None or random_actions or self.num_envs != 1 or self._has_episode_callbacks():
            return super()._sample(
                num_timesteps=num_timesteps,
                num_episodes=num_episodes,
                explore=explore,
                random_actions=random_actions,
                force_reset=force_reset,
            )
        env = self.env.unwrapped.envs[0]
        module = self.module
        dist_class = (
            module.get_exploration_action_dist_cls() if explore else module.get_inference_action_dist_cls()
        )
        # RLlib's forward_exploration/_inference switch a module in training mode to eval and back on every
        # call, a walk over all its submodules (a fifth of this loop's time, profiled); eval mode once.
        if module.training:
            module.eval()
        forward = module._forward_exploration if explore else module._forward_inference
        space = self.env.single_action_space
        for_env = self._action_for_env_fn()
        self._ongoing_episodes_for_metrics.clear()
        episodes, steps = [], 0
        seed = self._seed  # RLlib seeds the first reset of every episode-mode call
        planned = getattr(env.unwrapped, "remaining", None)
        for k in range(int(num_episodes)):
            if k and planned is not None and planned() == 0:
                # The plan ran out inside this call (after_failure="abort_layer" drops the rest of a
                # layer): no placeholder episodes, whose env steps would count against the budget.
                break
            started = time.perf_counter()
            obs, info = env.reset(seed=seed)
            seed = None
            observations, infos, actions, rewards = [obs], [info], [], []
            terminated = truncated = False
            while not (terminated or truncated):
                if self.act_hook is not None:
                    action = self.act_hook(obs, explore)
                else:
                    with torch.no_grad():
                        batch = torch.from_numpy(np.asarray(obs, np.float32)[None]).to(self._device)
                        inputs = forward({Columns.OBS: batch})[Columns.ACTION_DIST_INPUTS]
                        dist = dist_class.from_logits(inputs)
                        if not explore:
                            dist = dist.to_deterministic()
                        action = dist.sample()[0].cpu().numpy()
                obs, reward, terminated, truncated, info = env.step(for_env(action, space))
                observations.append(obs)
                infos.append(info)
                actions.append(action)
                rewards.append(float(reward))
            episode = SingleAgentEpisode(
                observations=observations,
                infos=infos,
                actions=actions,
                rewards=rewards,
                terminated=bool(terminated),
                truncated=bool(truncated),
                observation_space=self.env.single_observation_space,
                action_space=space,
                len_lookback_buffer=0,
            )
            episode._start_time, episode._last_step_time = started, time.perf_counter()
            episodes.append(episode.to_numpy() if self.episodes_to_numpy else episode)
            steps += len(actions)
        self._needs_initial_reset = True  # as RLlib's episode mode: the next call resets (and seeds) again
        self._done_episodes_for_metrics.extend(episodes)
        self._log_env_steps(metric=self._metrics_num_env_steps_sampled, num_steps=steps)
        self._increase_sampled_metrics(steps, len(episodes))
        return episodes

    def _action_for_env_fn(self):
        """What RLlib's NormalizeAndClipActions does to a sampled action before the env sees it (for a
        bounded float Box, `unsquash_action`'s arithmetic without its walk over the space's structure)."""
        space = self.env.single_action_space
        if self.config.normalize_actions:
            box = isinstance(space, gym.spaces.Box) and space.dtype in (np.float32, np.float64)
            if box and np.all(space.bounded_below) and np.all(space.bounded_above):
                low, high = space.low, space.high
                span = high - low
                return lambda action, _: np.clip(low + (action + 1.0) * span / 2.0, low, high)
            return unsquash_action
        if self.config.clip_actions:
            return clip_action
        return lambda action, _: action

    def _has_episode_callbacks(self) -> bool:
        """Whether anything wants RLlib's per-episode callbacks (the lean loop makes none)."""
        if any(type(c).__module__.split(".")[0] != "ray" for c in self._callbacks):
            return True
        names = ("created", "start", "step", "end")
        return any(getattr(self.config, f"callbacks_on_episode_{n}", None) for n in names)
