"""SAC learner speed: the fused update (this project's default) against the batch path it replaced, RLlib's
stock SAC learner and SB3's SAC; then a lone CO-PILOT trial on both paths, interleaved.

All learners train 256x256 networks on batches of 256 transitions from the same replay data, collected
with random actions on a goal-conditioned point env (`copilot_ray.envs.make("maze-point")` with its
Dict observation flattened to concat(observation, desired_goal); a tiny numpy point env if that
package is not importable). Everything runs in one process with the same torch thread count.

    (a) fused: `use_fast_learner(SACConfig())` + `FlatTransitionBuffer` on the learner's device +
        `learner.update_from_replay`: the whole step, replay sampling included, as one function over
        device tensors with the finite check on the device (`--compile`: also torch.compile'd).
    (b) batches: the path before it, `use_fast_learner(..., fused_update=False)` + `FlatTransitionBuffer`
        sampled on the host + `update_from_buffer` with `--steps-per-call` gradient steps per
        `learner_group.update(batch=...)` call (RLlib's minibatch loop, the finite check on the host).
    (c) stock: RLlib 2.60 default SAC module + `SACTorchLearner`, its default training path:
        `PrioritizedEpisodeReplayBuffer.sample(...)` -> `learner_group.update(episodes=...)`
        (learner connector included), one gradient step per call. Priority updates are left out
        (they would only make it slower).
    (d) SB3: `SAC("MlpPolicy", ...)` with net_arch [256, 256], `model.train(gradient_steps=1,
        batch_size=256)` per update, i.e. SB3's default `train_freq=1, gradient_steps=1` loop (skipped
        when stable-baselines3 is not installed).

Usage (from the repository root):

    PYTHONPATH=. RAY_AUTH_MODE=disabled .venv/bin/python benchmarks/learner_speed.py \
        --updates 256 --stock-updates 16 --repeats 7

Prints updates/s per system and repeat (the systems timed in turns, so load drift on a shared machine
hits them alike), medians and paired ratios; the traversal's sampling per env step with RLlib's env
runner and with the lean `TraversalEnvRunner` (`--sampling-passes`); then the end-to-end section: one CO-PILOT trial per path
(four-rooms, K = 5, one update per env step, evaluation off; `--e2e-paths`: "before" = the batch path
and RLlib's env runner, "after" = the fused update and the lean traversal loop, `fused_only` and
`lean_only` in between) built side by side in this process and trained in alternating iterations after
one warm-up iteration each, with env steps/s per iteration and the paired median ratios against the
first path. The last line is `ratio_vs_sb3=<x>` (the fused path; nan without SB3).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from throughput import PHASES, phase_shares  # noqa: E402  (the trial's phases, as the throughput benchmarks)

BATCH_SIZE = 256
HIDDEN = (256, 256)


# ----------------------------------------------------------------------------------------- envs
class FlattenGoalObs(gym.ObservationWrapper):
    """Dict(observation, achieved_goal, desired_goal) -> Box concat(observation, desired_goal)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        spaces = env.observation_space.spaces
        low = np.concatenate([spaces["observation"].low, spaces["desired_goal"].low]).astype(np.float32)
        high = np.concatenate([spaces["observation"].high, spaces["desired_goal"].high]).astype(np.float32)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)

    def observation(self, obs):
        return np.concatenate([obs["observation"], obs["desired_goal"]]).astype(np.float32)


class TinyPointGoalEnv(gym.Env):
    """Fallback: point in [0, 1]^2, obs = (position, goal), action = step in [-1, 1]^2 * 0.05."""

    def __init__(self):
        self.observation_space = gym.spaces.Box(0.0, 1.0, (4,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self._pos, self._goal = self.np_random.uniform(0, 1, (2, 2))
        return self._obs(), {}

    def _obs(self):
        return np.concatenate([self._pos, self._goal]).astype(np.float32)

    def step(self, action):
        self._pos = np.clip(self._pos + 0.05 * np.clip(action, -1, 1), 0.0, 1.0)
        success = bool(np.linalg.norm(self._pos - self._goal) < 0.05)
        return self._obs(), (0.0 if success else -1.0), success, False, {"success": success}


def make_env(max_steps: int = 50) -> tuple[gym.Env, str]:
    try:
        from copilot_ray.envs import make

        env, name = FlattenGoalObs(make("maze-point")), "maze-point (flattened)"
    except Exception as exc:  # the env package is built in parallel; fall back if it is not there
        print(f"copilot_ray.envs.make('maze-point') unavailable ({exc!r}); using TinyPointGoalEnv")
        env, name = TinyPointGoalEnv(), "TinyPointGoalEnv"
    return gym.wrappers.TimeLimit(env, max_episode_steps=max_steps), name


def collect_random_episodes(env: gym.Env, num_steps: int, seed: int = 0):
    """Random-action rollouts -> list of (obs[T+1], actions[T], rewards[T], terminated, truncated)."""
    rng = np.random.default_rng(seed)
    episodes, steps = [], 0
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    while steps < num_steps:
        obs_l, act_l, rew_l = [obs], [], []
        term = trunc = False
        while not (term or trunc):
            a = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
            obs, r, term, trunc, _ = env.step(a)
            obs_l.append(obs), act_l.append(a), rew_l.append(float(r))
            steps += 1
        episodes.append((np.asarray(obs_l), np.asarray(act_l), np.asarray(rew_l, np.float32), term, trunc))
        obs, _ = env.reset()
    return episodes


def to_rllib_episodes(raw, observation_space, action_space):
    from ray.rllib.env.single_agent_episode import SingleAgentEpisode

    out = []
    for obs, acts, rews, term, trunc in raw:
        ep = SingleAgentEpisode(observation_space=observation_space, action_space=action_space)
        ep.add_env_reset(observation=obs[0], infos={})
        for t in range(len(acts)):
            last = t == len(acts) - 1
            ep.add_env_step(
                observation=obs[t + 1],
                action=acts[t],
                reward=float(rews[t]),
                infos={},
                terminated=bool(term and last),
                truncated=bool(trunc and last),
            )
        out.append(ep.to_numpy())
    return out


# ------------------------------------------------------------------------------------ systems
def timed(fn: Callable[[], None], num_updates: int) -> float:
    t0 = time.perf_counter()
    fn()
    return num_updates / (time.perf_counter() - t0)


def build_stock(obs_space, act_space, episodes):
    """RLlib's default SAC learner group plus its default prioritized episode replay buffer."""
    from ray.rllib.algorithms.sac import SACConfig
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME
    from ray.rllib.utils.replay_buffers import PrioritizedEpisodeReplayBuffer

    config = SACConfig().environment(observation_space=obs_space, action_space=act_space)
    config.rl_module(model_config={"fcnet_hiddens": list(HIDDEN)})
    lg = config.build_learner_group()
    rb_cfg = config.replay_buffer_config
    buffer = PrioritizedEpisodeReplayBuffer(capacity=rb_cfg["capacity"], alpha=rb_cfg["alpha"])
    buffer.add(episodes)
    timesteps = {NUM_ENV_STEPS_SAMPLED_LIFETIME: buffer.get_num_timesteps()}

    def run(n: int) -> None:
        for _ in range(n):
            eps = buffer.sample(
                num_items=BATCH_SIZE,
                n_step=config.n_step,
                gamma=config.gamma,
                beta=rb_cfg["beta"],
                sample_episodes=True,
            )
            lg.update(episodes=eps, timesteps=timesteps)

    return run, lg


def build_batches(obs_space, act_space, episodes, steps_per_call: int, torch_threads: int):
    """The path before the fused update: the replay sampled on the host, RLlib's `update(batch=...)` per
    chunk of steps."""
    from ray.rllib.algorithms.sac import SACConfig
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

    from copilot_ray.algorithms.gc_sac import (
        FlatTransitionBuffer,
        host_sampler,
        update_from_buffer,
        use_fast_learner,
    )

    config = use_fast_learner(
        SACConfig().environment(observation_space=obs_space, action_space=act_space),
        hidden=HIDDEN,
        torch_threads=torch_threads,
        fused_update=False,
    )
    lg = config.build_learner_group()
    buffer = FlatTransitionBuffer(1_000_000)
    buffer.add_episodes(episodes)
    sample = host_sampler(buffer)
    timesteps = {NUM_ENV_STEPS_SAMPLED_LIFETIME: buffer.num_added}

    def run(n: int) -> None:
        done = 0
        while done < n:
            k = min(steps_per_call, n - done)
            update_from_buffer(lg, sample, k, BATCH_SIZE, timesteps)
            done += k

    return run, lg


def build_fused(
    obs_space, act_space, episodes, steps_per_call: int, torch_threads: int, compile_update=False
):
    """The fused update: replay on the learner's device, `update_from_replay` per chunk of steps (a
    chunk is what a trial's sampling round asks for)."""
    from ray.rllib.algorithms.sac import SACConfig
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

    from copilot_ray.algorithms.gc_sac import FlatTransitionBuffer, use_fast_learner

    config = use_fast_learner(
        SACConfig().environment(observation_space=obs_space, action_space=act_space),
        hidden=HIDDEN,
        torch_threads=torch_threads,
        compile_update=compile_update,
    )
    learner = config.build_learner_group()._learner
    buffer = FlatTransitionBuffer(1_000_000, device=learner.device)
    buffer.add_episodes(episodes)
    timesteps = {NUM_ENV_STEPS_SAMPLED_LIFETIME: buffer.num_added}

    def run(n: int) -> None:
        done = 0
        while done < n:
            k = min(steps_per_call, n - done)
            learner.update_from_replay(buffer, k, BATCH_SIZE, timesteps)
            done += k

    return run, learner


def build_sb3(env: gym.Env, raw):
    from stable_baselines3 import SAC

    model = SAC(
        "MlpPolicy",
        env,
        batch_size=BATCH_SIZE,
        learning_starts=0,
        buffer_size=1_000_000,
        policy_kwargs={"net_arch": list(HIDDEN)},
        device="cpu",
        seed=0,
        verbose=0,
    )
    from stable_baselines3.common.logger import configure

    model.set_logger(configure(None, []))
    rb = model.replay_buffer
    for obs, acts, rews, term, _trunc in raw:
        t = len(acts)
        dones = np.zeros(t, dtype=np.float32)
        dones[-1] = float(term)
        for i in range(t):
            rb.add(obs[i][None], obs[i + 1][None], acts[i][None], rews[i : i + 1], dones[i : i + 1], [{}])

    def run(n: int) -> None:
        for _ in range(n):
            model.train(gradient_steps=1, batch_size=BATCH_SIZE)

    return run, model


def traversal_sampling(passes: int, depth: int, torch_threads: int) -> dict[str, list[float]]:
    """ms per env step of sampling a traversal (maze-point four-rooms, 2 training tasks, K = `depth`,
    random interior sub-goals, tau_max 25, 8 sub-tasks per `sample` call, as GoalSAC asks) with RLlib's
    `SingleAgentEnvRunner` and with `TraversalEnvRunner`, the same weights, in turns, `passes` times."""
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    from copilot_ray import envs
    from copilot_ray.algorithms.sac.algorithm import GoalSACConfig
    from copilot_ray.algorithms.sac.traversal_runner import TraversalEnvRunner

    config = (
        GoalSACConfig()
        .environment("maze-point", env_config={"layout": "four-rooms"})
        .debugging(seed=5)
        .agent(tau_max=25)
    )
    config.validate()
    torch.set_num_threads(torch_threads)
    starts, goals = envs.make("maze-point", layout="four-rooms").unwrapped.tasks("train")
    rng = np.random.default_rng(0)
    inner = rng.uniform(0.1, 0.9, (2, 2**depth - 1, 2))
    trees = np.concatenate([starts[:2, None], inner, goals[:2, None]], axis=1).astype(np.float32)
    runners = {"rllib": SingleAgentEnvRunner(config=config), "lean": TraversalEnvRunner(config=config)}
    runners["lean"].set_state(runners["rllib"].get_state())
    ms: dict[str, list[float]] = {name: [] for name in runners}
    for i in range(passes):
        for name, runner in runners.items():
            env = runner.env.unwrapped
            env.call("load_plan", trees, depth, np.arange(2))
            steps, t0 = 0, time.perf_counter()
            while env.call("remaining")[0]:
                steps += sum(len(e) for e in runner.sample(num_episodes=8, explore=True))
            ms[name].append(1000 * (time.perf_counter() - t0) / steps)
            print(
                f"  traversal sampling, pass {i}: {name} {ms[name][-1]:.2f} ms per env step ({steps})",
                flush=True,
            )
    for runner in runners.values():
        runner.stop()
    return ms


# A lone trial's paths: (the settings fused_update, lean_traversal). "before" is the commit
# before the fused update and the lean loop; "after" this checkout's default; the other two split the gain.
E2E_PATHS = {
    "before": (False, False),
    "fused_only": (True, False),
    "lean_only": (False, True),
    "after": (True, True),
}


def copilot_end_to_end(
    paths: list[str], iterations: int, tasks: int, depth: int, torch_threads: int
) -> tuple[dict[str, list[float]], dict[str, dict[str, float]]]:
    """Env steps/s per iteration of a lone CO-PILOT trial (maze-point four-rooms, K = `depth`, b = 1,
    `tasks` tasks per iteration, one SAC update per env step, evaluation off) per path of `E2E_PATHS`:
    each built in this process, one warm-up iteration each, then `iterations` measured iterations of
    each in turns (never at the same time: each is a lone trial while it runs). Also returns, per path,
    each phase's wall time per env step over the measured iterations (ms; `throughput.phase_shares`'s
    phases: the traversal less its SAC updates, the updates, the planner, the cost model, the rest)."""
    import ray

    from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
    from copilot_ray.keys import ENV_STEPS, TIME_PREFIX, metric_path, result_value

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    algos = {}
    try:
        for name in paths:
            fused, lean = E2E_PATHS[name]
            config = (
                CoPilotConfig()
                .environment("maze-point", env_config={"layout": "four-rooms"})
                .resources(num_cpus_for_main_process=torch_threads)
                .training(num_steps_sampled_before_learning_starts=256)
                .debugging(seed=0)
                # A short planner warm start: it spends no env steps, only the first iteration's time.
                .copilot(
                    tree_depth=depth,
                    repetitions=1,
                    task_batch_size=tasks,
                    eval_interval=0,
                    planner_warm_start=5,
                )
            )
            config.fused_update = fused
            config.lean_traversal = lean
            algos[name] = config.build_algo()
        rates: dict[str, list[float]] = {name: [] for name in algos}
        spent = {name: {p: 0.0 for p in (*PHASES, "wall", "env_steps")} for name in algos}
        for i in range(iterations + 1):
            for name, algo in algos.items():
                before = algo.metrics.peek(metric_path(ENV_STEPS), default=0)
                t0 = time.perf_counter()
                result = algo.train()
                wall = time.perf_counter() - t0
                steps = result_value(result, ENV_STEPS) - before
                if i > 0:  # the first: the planner's warm start, learning_starts, lazy building
                    rates[name].append(steps / wall)
                    for p in PHASES:
                        spent[name][p] += float(result_value(result, TIME_PREFIX + p) or 0.0)
                    spent[name]["wall"] += wall
                    spent[name]["env_steps"] += steps
                    print(f"  end to end, iteration {i}: {name} {steps / wall:.1f} env steps/s", flush=True)
        per_step = {}
        for name, t in spent.items():
            ms = 1000.0 * t["wall"] / max(t["env_steps"], 1.0)
            per_step[name] = {p: share * ms for p, share in phase_shares(t, t["wall"]).items()}
        return rates, per_step
    finally:
        for algo in algos.values():
            algo.stop()
        ray.shutdown()


# --------------------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> float:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--updates", type=int, default=256, help="gradient updates timed per repeat (ours, SB3)")
    p.add_argument("--stock-updates", type=int, default=16, help="updates timed per repeat for stock RLlib")
    p.add_argument("--warmup", type=int, default=32, help="untimed warm-up updates per system")
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--steps-per-call", type=int, default=16, help="gradient steps per learner call (ours)")
    p.add_argument("--torch-threads", type=int, default=2)
    p.add_argument("--data-steps", type=int, default=20_000, help="random env steps put into the buffers")
    p.add_argument("--compile", action="store_true", help="also time the fused update torch.compile'd")
    p.add_argument("--skip-stock", action="store_true")
    p.add_argument("--skip-sb3", action="store_true")
    p.add_argument("--skip-end-to-end", action="store_true", help="skip the CO-PILOT loop measurement")
    p.add_argument(
        "--sampling-passes", type=int, default=2, help="traversal sampling passes per env runner (0: skip)"
    )
    p.add_argument("--e2e-iterations", type=int, default=3, help="measured CO-PILOT iterations per path")
    p.add_argument(
        "--e2e-paths",
        nargs="+",
        choices=list(E2E_PATHS),
        default=["before", "after"],
        help="which lone trials to alternate (default: before after)",
    )
    p.add_argument("--e2e-tasks", type=int, default=1, help="tasks per CO-PILOT iteration (b = 1)")
    p.add_argument("--e2e-depth", type=int, default=5, help="K of the CO-PILOT trial")
    args = p.parse_args(argv)
    for flag in ("updates", "stock_updates", "repeats", "steps_per_call", "torch_threads", "e2e_iterations"):
        if getattr(args, flag) < 1:
            p.error(f"--{flag.replace('_', '-')} {getattr(args, flag)!r} is invalid: must be >= 1")

    torch.set_num_threads(args.torch_threads)
    env, env_name = make_env()
    obs_space, act_space = env.observation_space, env.action_space
    raw = collect_random_episodes(env, args.data_steps)
    episodes = to_rllib_episodes(raw, obs_space, act_space)
    print(
        f"env={env_name} obs_dim={obs_space.shape[0]} act_dim={act_space.shape[0]} "
        f"transitions={sum(len(e) for e in episodes)} batch={BATCH_SIZE} hidden={list(HIDDEN)} "
        f"torch_threads={args.torch_threads} steps_per_call={args.steps_per_call}"
    )

    systems: dict[str, tuple[Callable[[int], None], int]] = {}
    shape = (obs_space, act_space, episodes, args.steps_per_call, args.torch_threads)
    systems["fused"] = (build_fused(*shape)[0], args.updates)
    systems["batches"] = (build_batches(*shape)[0], args.updates)
    if args.compile:
        systems["fused_compiled"] = (build_fused(*shape, compile_update=True)[0], args.updates)
    if not args.skip_sb3:
        try:
            systems["sb3"] = (build_sb3(env, raw)[0], args.updates)
        except ImportError as exc:
            print(f"SB3 skipped: {exc}")
    if not args.skip_stock:
        stock_run, _ = build_stock(obs_space, act_space, episodes)
        systems["stock"] = (stock_run, args.stock_updates)
    torch.set_num_threads(args.torch_threads)  # learners may have set it; keep all systems equal

    for run, _ in systems.values():
        run(args.warmup)

    rates: dict[str, list[float]] = {name: [] for name in systems}
    for rep in range(args.repeats):  # interleaved, so load drift hits every system alike
        for name, (run, n) in systems.items():
            rate = timed(lambda run=run, n=n: run(n), n)
            rates[name].append(rate)
        print(f"repeat {rep}: " + "  ".join(f"{k}={v[-1]:.1f}" for k, v in rates.items()) + " updates/s")

    med = {name: statistics.median(v) for name, v in rates.items()}
    print("median updates/s: " + ", ".join(f"{k}={v:.1f}" for k, v in med.items()))
    # Paired ratios (same repeat, timed back to back) are more robust to a shared machine's load
    # bursts than ratios of medians; both are printed, the paired median is the headline.
    for other in ("batches", "fused_compiled", "stock", "sb3"):
        if other in med:
            paired = statistics.median(o / x for o, x in zip(rates["fused"], rates[other], strict=True))
            print(
                f"fused/{other}: paired median={paired:.2f}  ratio of medians={med['fused'] / med[other]:.2f}"
            )
    if args.sampling_passes > 0:
        ms = traversal_sampling(args.sampling_passes, args.e2e_depth, args.torch_threads)
        paired = statistics.median(r / x for r, x in zip(ms["rllib"], ms["lean"], strict=True))
        print(
            f"traversal sampling (four-rooms, K={args.e2e_depth}, 2 tasks), median ms per env step: "
            + ", ".join(f"{k}={statistics.median(v):.2f}" for k, v in ms.items())
            + f"; rllib/lean paired median={paired:.2f}"
        )
    if not args.skip_end_to_end:
        e2e, per_step = copilot_end_to_end(
            args.e2e_paths, args.e2e_iterations, args.e2e_tasks, args.e2e_depth, args.torch_threads
        )
        base = args.e2e_paths[0]
        paired = {
            name: statistics.median(x / b for x, b in zip(rates_, e2e[base], strict=True))
            for name, rates_ in e2e.items()
            if name != base
        }
        print(
            f"CO-PILOT end to end (four-rooms, K={args.e2e_depth}, {args.e2e_tasks} task(s) per iteration, "
            f"1 update per env step), median env steps/s: "
            + ", ".join(f"{k}={statistics.median(v):.1f}" for k, v in e2e.items())
            + "; paired medians: "
            + ", ".join(f"{name}/{base}={r:.2f}" for name, r in paired.items())
        )
        for name, costs in per_step.items():
            print(
                f"  {name}: {sum(costs.values()):.2f} ms per env step: "
                + ", ".join(f"{p.removesuffix('_s')} {ms:.2f}" for p, ms in costs.items())
            )
    ratio_sb3 = (
        statistics.median(o / x for o, x in zip(rates["fused"], rates["sb3"], strict=True))
        if "sb3" in med
        else float("nan")
    )
    print(f"ratio_vs_sb3={ratio_sb3:.3f}")
    return ratio_sb3


if __name__ == "__main__":
    main()
