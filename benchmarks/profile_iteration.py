"""Where one training iteration's wall time goes, by Python function (cProfile), on the CPU or a GPU.

    PYTHONPATH=. python benchmarks/profile_iteration.py [--algorithm copilot] [--gpus 1] [--cpus 2]
        [--warm-start 5] [--iterations 1] [--top 30]

Builds the algorithm as `benchmarks/device_throughput.py` does (in this process, the learner on
`--gpus` of a GPU), trains `--iterations` iterations under cProfile and prints the functions with the
most cumulative and own time. On a GPU, time spent waiting for the device shows up in the call that
synchronises (`.item()`, `.cpu()`, `.numpy()`), which is what this is for.
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from device_throughput import _config  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--algorithm", default="copilot")
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--gpus", type=float, default=0.0)
    p.add_argument("--cpus", type=int, default=2)
    p.add_argument("--warm-start", type=int, default=5)
    p.add_argument("--eval-every", type=int, default=3200)
    p.add_argument("--iterations", type=int, default=1)
    p.add_argument("--top", type=int, default=30)
    args = p.parse_args(argv)
    for flag, value, ok in (
        ("--gpus", args.gpus, args.gpus >= 0),
        ("--cpus", args.cpus, args.cpus >= 1),
        ("--iterations", args.iterations, args.iterations >= 1),
    ):
        if not ok:
            print(f"error: {flag} {value!r} is invalid: out of range", file=sys.stderr)
            return 2
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    import ray

    ray.init(num_cpus=args.cpus, include_dashboard=False, log_to_driver=False)
    try:
        config = _config(
            args.algorithm, args.layout, args.eval_every, args.warm_start, 0, args.cpus, args.gpus
        )
        algo = config.build_algo()
        profile = cProfile.Profile()
        t0 = time.perf_counter()
        profile.enable()
        for _ in range(args.iterations):
            result = algo.train()
        profile.disable()
        wall = time.perf_counter() - t0
        from copilot_ray import keys

        steps = keys.result_value(result, keys.ENV_STEPS)
        print(f"{args.iterations} iteration(s), {steps} env steps, {wall:.1f} s (under cProfile)")
        stats = pstats.Stats(profile)
        stats.sort_stats("cumulative").print_stats(args.top)
        stats.sort_stats("tottime").print_stats(args.top)
        algo.stop()
    finally:
        ray.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
