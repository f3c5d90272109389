"""Does torch.compile make the fast SAC learner's updates faster? Eager and compiled, interleaved.

    PYTHONPATH=. .venv/bin/python benchmarks/learner_compile.py [--what forward_train] [--torch-threads 1]
        [--updates 256] [--repeats 5]

Two learner groups of the fast GC-SAC learner (256x256 networks, batches of 256 from the same random
four-rooms data as `benchmarks/learner_speed.py`), one through RLlib's `torch_compile_learner` with
`--what` compiled (`forward_train`: the module's forward passes; `complete_update`: the whole update,
graph breaks included), timed in turns (`--updates` gradient steps each, `--repeats` times) after an
untimed warm-up that includes the compilation. Prints how many graphs dynamo compiled (0: nothing was
reached, the "compiled" group ran eagerly), each repeat, the medians and their ratio. On a GPU this is
where a compiled update would pay most (one launch instead of many); run it there with `--device cuda`.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("RAY_AUTH_MODE", "disabled")

from learner_speed import BATCH_SIZE, HIDDEN, collect_random_episodes, make_env, to_rllib_episodes  # noqa: E402


def build(env, episodes, what: str | None, threads: int, device: str):
    """One learner group (compiled where `what` is given) and a function doing n gradient steps on it."""
    from ray.rllib.algorithms.sac import SACConfig
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

    from copilot_ray.algorithms.gc_sac import (
        FlatTransitionBuffer,
        host_sampler,
        update_from_buffer,
        use_fast_learner,
    )

    config = SACConfig().environment(observation_space=env.observation_space, action_space=env.action_space)
    if what is not None:
        config = config.framework(torch_compile_learner=True, torch_compile_learner_what_to_compile=what)
    if device == "cuda":
        config = config.learners(num_gpus_per_learner=1)
    group = use_fast_learner(config, hidden=HIDDEN, torch_threads=threads).build_learner_group()
    buffer = FlatTransitionBuffer(100_000)
    buffer.add_episodes(episodes)
    timesteps = {NUM_ENV_STEPS_SAMPLED_LIFETIME: buffer.num_added}
    return lambda n: update_from_buffer(group, host_sampler(buffer), n, BATCH_SIZE, timesteps)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--what", default="forward_train", choices=("forward_train", "complete_update"))
    p.add_argument("--torch-threads", type=int, default=1)
    p.add_argument("--updates", type=int, default=256, help="gradient steps per timed turn")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    args = p.parse_args(argv)
    for flag, value in (
        ("--torch-threads", args.torch_threads),
        ("--updates", args.updates),
        ("--repeats", args.repeats),
    ):
        if value < 1:
            print(f"error: {flag} {value!r} is invalid: must be an integer >= 1", file=sys.stderr)
            return 2
    env, _ = make_env()
    episodes = to_rllib_episodes(collect_random_episodes(env, 5000), env.observation_space, env.action_space)
    runs = {
        "eager": build(env, episodes, None, args.torch_threads, args.device),
        "compiled": build(env, episodes, args.what, args.torch_threads, args.device),
    }
    from torch._dynamo.utils import counters

    t0 = time.perf_counter()
    runs["compiled"](64)
    # What dynamo really compiled: 0 graphs means the compiled group ran eagerly (nothing was reached).
    graphs = counters["stats"].get("unique_graphs", 0)
    print(
        f"compiled warm-up (64 steps, compilation included): {time.perf_counter() - t0:.1f} s, {graphs} graph(s)"
    )
    runs["eager"](64)
    rates: dict[str, list[float]] = {k: [] for k in runs}
    for i in range(args.repeats):
        for name, run in runs.items():
            t0 = time.perf_counter()
            run(args.updates)
            rates[name].append(args.updates / (time.perf_counter() - t0))
        print(f"repeat {i}: " + ", ".join(f"{k} {v[-1]:.1f}" for k, v in rates.items()) + " updates/s")
    eager, compiled = (statistics.median(rates[k]) for k in ("eager", "compiled"))
    print(
        f"{args.what}, {args.torch_threads} torch thread(s), {args.device}: median updates/s eager {eager:.1f}, "
        f"compiled {compiled:.1f}; ratio {compiled / eager:.3f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
