"""The traversal's env runner: RLlib's `SingleAgentEnvRunner` with a lean loop for whole sub-tasks.

`GoalSAC` samples the traversal one sub-task at a time (`sample(num_episodes=k)`). RLlib's loop spends
most of an env step around it: the env-to-module and module-to-env connector pipelines (a dozen
pieces, each walking the batch and the episodes), an episode `add_env_step` with its lookback buffers,
three episode callbacks and several timers, per step. `TraversalEnvRunner._sample` does the same
steps without them, for episode sampling:

    obs -> torch [1, d] -> the module's forward_exploration (forward_inference when not exploring),
           in eval mode, set once (RLlib switches modes twice per call)
        -> the module's action distribution: sampled as RLlib samples it (loc + noise * scale, squashed),
           its noise from the runner's own generator (its deterministic twin when not exploring)
        -> unsquash (normalize_actions) or clip (clip_actions) for the env, as RLlib's connector
           computes it -> env.step

and builds each finished sub-task's `SingleAgentEpisode` once, from its lists. These are the calls
RLlib's pipeline makes, in the same order, so for the same weights and the same noise both loops give
the same episodes (`tests/test_traversal_runner.py`). The env is reset at the start of every call and
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

    The loop is a generator (`subtask_steps`: it yields each observation and is sent the action), so
    that one loop serves a runner acting alone (`_sample`, with `policy`) and a seed stack stepping
    several runners' envs together with one batched forward pass (`algorithms.sac.seed_stack`).
    Exploration noise comes from the runner's own generator (`draw_noise`), not torch's global one:
    a runner draws the same noise whatever else runs in its process."""

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
        if not self.samples_lean(num_episodes, random_actions):
            return super()._sample(
                num_timesteps=num_timesteps,
                num_episodes=num_episodes,
                explore=explore,
                random_actions=random_actions,
                force_reset=force_reset,
            )
        return run_alone(self.subtask_steps(int(num_episodes), explore), self.policy(explore))

    def samples_lean(self, num_episodes: int | None, random_actions: bool = False) -> bool:
        """Whether `sample(num_episodes=...)` runs the lean loop (else RLlib's own)."""
        return not (
            num_episodes is None
            or random_actions
            or self.num_envs != 1
            or self._has_episode_callbacks()
            or not isinstance(self.env.single_action_space, gym.spaces.Box)
        )

    # ------------------------------------------------------------------ acting
    @property
    def action_noise(self) -> torch.Generator:
        """The runner's exploration-noise generator, seeded by the run's seed and the runner's index."""
        gen = getattr(self, "_action_noise", None)
        if gen is None:
            seed = 0 if self.config.seed is None else int(self.config.seed)
            gen = torch.Generator().manual_seed(seed * 1_000_003 + int(self.worker_index or 0))
            self._action_noise = gen
        return gen

    def draw_noise(self) -> torch.Tensor:
        """One env step's standard-normal exploration noise [1, A] (CPU, the runner's generator)."""
        return torch.randn((1, *self.env.single_action_space.shape), generator=self.action_noise)

    def policy(self, explore: bool):
        """obs -> action of the runner's module: its squashed Gaussian sampled with `draw_noise`
        (as RLlib's `sample()`: loc + noise * scale, squashed), or its deterministic action."""
        module = self.module
        dist_class = (
            module.get_exploration_action_dist_cls() if explore else module.get_inference_action_dist_cls()
        )
        # RLlib's forward_exploration/_inference switch a module in training mode to eval and back on every
        # call, a walk over all its submodules (a fifth of this loop's time, profiled); eval mode once.
        if module.training:
            module.eval()
        forward = module._forward_exploration if explore else module._forward_inference

        @torch.no_grad()
        def act(obs: np.ndarray) -> np.ndarray:
            batch = torch.from_numpy(np.asarray(obs, np.float32)[None]).to(self._device)
            dist = dist_class.from_logits(forward({Columns.OBS: batch})[Columns.ACTION_DIST_INPUTS])
            if not explore:
                return dist.to_deterministic().sample()[0].cpu().numpy()
            gaussian = dist._dist  # noqa: SLF001 - its Normal, sampled with the runner's own noise
            unsquashed = gaussian.loc + self.draw_noise().to(gaussian.loc.device) * gaussian.scale
            return dist._squash(unsquashed)[0].cpu().numpy()  # noqa: SLF001

        return act

    # ------------------------------------------------------------------ the loop
    def subtask_steps(self, num_episodes: int, explore: bool):
        """The lean loop over `num_episodes` sub-tasks as a generator: yields each observation, is sent
        its action (or the action and its motion, `TraversalEnv.step_to`'s arguments, where the caller
        moved the agent itself), and returns the episodes (logged into the runner's metrics as
        `_sample` logs them)."""
        env = self.env.unwrapped.envs[0]
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
                sent = yield obs  # the action, or (the action, its motion: where a seed stack moved the agent)
                action, motion = sent if isinstance(sent, tuple) else (sent, None)
                if motion is None:
                    obs, reward, terminated, truncated, info = env.step(for_env(action, space))
                else:
                    obs, reward, terminated, truncated, info = env.unwrapped.step_to(*motion)
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


def run_alone(steps, act):
    """Drives one `subtask_steps` generator with `act(obs) -> action`; returns its episodes."""
    try:
        obs = next(steps)
        while True:
            obs = steps.send(act(obs))
    except StopIteration as done:
        return done.value


def run_together(steps: dict, act, move=None) -> dict:
    """Drives several `subtask_steps` generators (one per runner) in one loop: at every env step one
    `act(ids, observations) -> actions` for every runner whose sub-task is under way, and with `move`
    one `move(ids, actions) -> motions` moving all their agents at once (else each env steps its own).
    Returns {id: its episodes}, or {id: the exception its env raised} for a runner whose stepping
    failed (the others go on); an exception of `act` or `move` itself is raised."""
    observations, out = {}, {}

    def advance(i, sent, first=False):
        try:
            observations[i] = next(steps[i]) if first else steps[i].send(sent)
        except StopIteration as done:
            observations.pop(i, None)
            out[i] = done.value
        except Exception as err:  # noqa: BLE001 - one runner's failure is its own
            observations.pop(i, None)
            out[i] = err

    for i in steps:
        advance(i, None, first=True)
    while observations:
        ids = sorted(observations)
        actions = act(ids, [observations[i] for i in ids])
        sent = actions if move is None else list(zip(actions, move(ids, actions), strict=True))
        for i, value in zip(ids, sent, strict=True):
            advance(i, value)
    return out
