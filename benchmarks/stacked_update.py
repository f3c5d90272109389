"""SAC updates/s with N seeds stacked in one update (`sac_step.SACStep` over N seeds) against one seed's
fused step (the same step at N = 1), at this project's sizes (actor and twin critics [256, 256], batch
256, obs 4, action 2).

    PYTHONPATH=. python benchmarks/stacked_update.py [--seeds 1 2 4] [--seconds 5] [--threads 2] [--device cpu]

Rows, per device: "one seed, fused" (the learner's `SACStep`, N = 1, the path a trial takes today: its
updates/s is its seed-updates/s), then for each N "N stacked" (one `SACStep` for N seeds); on a GPU each also
"captured" (one CUDA graph per update, `graph_capture.CapturedCall`). Each row warms up for 3 calls,
then runs for `--seconds`; it prints updates/s of the stack and seed-updates/s (N x that). Each seed
samples its batch from its own ring of one replay inside the step (`FlatTransitionBuffer` with a ring per seed, random
transitions; one gather per column for all seeds, no host sync).

On a CPU compare "N stacked" at `--threads` T against T one-seed trials side by side, each on one
thread (`--threads 1` for the one-seed row): that is what stacking replaces on a two-core machine.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID

from copilot_ray.algorithms.gc_sac import use_fast_learner
from copilot_ray.algorithms.gc_sac.graph_capture import CapturedCall
from copilot_ray.algorithms.gc_sac.replay_buffer import FlatTransitionBuffer
from copilot_ray.algorithms.gc_sac.sac_step import SACStep

OBS, ACT, BATCH, CAPACITY = 4, 2, 256, 100_000


def _learner(device: str):
    space = gym.spaces.Box(0.0, 1.0, (OBS,), np.float32)
    cfg = SACConfig().environment(
        observation_space=space, action_space=gym.spaces.Box(-1.0, 1.0, (ACT,), np.float32)
    )
    cfg.learners(num_gpus_per_learner=1 if device == "cuda" else 0)
    return (
        use_fast_learner(cfg.debugging(seed=0), hidden=(256, 256), torch_threads=None)
        .build_learner_group()
        ._learner
    )


def _transitions(seed: int) -> dict[str, np.ndarray]:
    """CAPACITY random transitions of four-rooms' sizes."""
    rng = np.random.default_rng(seed)
    obs = rng.uniform(0, 1, (CAPACITY, OBS)).astype(np.float32)
    return {
        "obs": obs,
        "new_obs": np.clip(obs + rng.normal(0, 0.01, obs.shape), 0, 1).astype(np.float32),
        "actions": rng.uniform(-1, 1, (CAPACITY, ACT)).astype(np.float32),
        "rewards": np.full(CAPACITY, -1.0, np.float32),
        "terminateds": rng.random(CAPACITY) < 0.05,
    }


def _replay(num_seeds: int, device: torch.device) -> FlatTransitionBuffer:
    replay = FlatTransitionBuffer(CAPACITY, device, OBS, ACT, seeds=range(num_seeds))
    for seed in range(num_seeds):
        replay.add(_transitions(seed), seed=seed)
    return replay


def stacked_step(learner, n: int, device: str) -> SACStep:
    """One `SACStep` for `n` seeds, each with its own modules (the step views their weights), at
    `learner`'s settings."""
    config = learner.config.get_config_for_module(DEFAULT_MODULE_ID)
    seeds = [_learner(device) for _ in range(n)]
    return SACStep(
        [s.module[DEFAULT_MODULE_ID].unwrapped() for s in seeds],
        [s.curr_log_alpha[DEFAULT_MODULE_ID] for s in seeds],
        None,
        learner.target_entropy[DEFAULT_MODULE_ID],
        gamma=config.gamma,
        tau=config.tau,
        critic_loss="huber",
        seeds=range(n),
        lrs={"qf": config.critic_lr, "policy": config.actor_lr, "alpha": config.alpha_lr},
    )


def _rate(fn, seconds: float, device: torch.device) -> float:
    for _ in range(3):
        fn()
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    sync()
    start, calls = time.perf_counter(), 0
    while time.perf_counter() - start < seconds:
        fn()
        calls += 1
    sync()
    return calls / (time.perf_counter() - start)


def _row(name: str, seeds: int, fn, seconds: float, device: torch.device) -> None:
    try:
        rate = _rate(fn, seconds, device)
    except Exception as error:  # a row that fails says why; the others still run
        print(f"{name:<28} failed: {type(error).__name__}: {error}", flush=True)
        return
    print(f"{name:<28} {rate:10.1f} updates/s  {rate * seeds:10.1f} seed-updates/s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 4], help="stack sizes N")
    parser.add_argument("--seconds", type=float, default=5.0, help="timed seconds per row")
    parser.add_argument("--threads", type=int, default=2, help="torch threads (CPU rows)")
    parser.add_argument(
        "--device", choices=("cpu", "cuda"), default="cuda" if torch.cuda.is_available() else "cpu"
    )
    args = parser.parse_args()
    if min(args.seeds) < 1:
        parser.error(f"--seeds: every N must be >= 1, got {args.seeds}")
    torch.set_num_threads(args.threads)
    device = torch.device(args.device)
    learner = _learner(args.device)
    print(
        f"# device {device} ({torch.cuda.get_device_name() if device.type == 'cuda' else f'{args.threads} threads'}), "
        f"torch {torch.__version__}, batch {BATCH}, networks [256, 256]",
        flush=True,
    )

    one = FlatTransitionBuffer(CAPACITY, device)
    one.add(_transitions(0))
    fused = learner.fused_step()
    _row("one seed, fused", 1, lambda: fused.step(one.sample(BATCH)), args.seconds, device)
    for n in args.seeds:
        replay = _replay(n, device)
        step = stacked_step(learner, n, args.device)

        def run(step=step, replay=replay):
            return step.step(replay.sample(BATCH))

        _row(f"{n} stacked", n, run, args.seconds, device)
        if device.type == "cuda":
            _row(f"{n} stacked, captured", n, CapturedCall(run), args.seconds, device)


if __name__ == "__main__":
    main()
