"""Learning parity: copilot_ray's fast SAC path vs. RLlib's stock SAC path on a tiny 2-D reach task.

Both paths train on `ReachGoal2D` (point in [0, 1]^2, obs = (position, goal), success within 0.1 of
the goal) through a real `SingleAgentEnvRunner` with the agent updater CO-PILOT uses, exactly as
tests/test_gc_sac_learning.py does (its `ReachGoal2D`, `train` and `success_rate` are imported from
there): same env, env-step budget, batch (64), learning rates (1e-3), gamma (0.95), one gradient step
per env step after 500 steps, each path its own module, learner and buffer.

    (a) fast: `use_fast_learner` (SB3-shaped 64x64 nets, fused GC-SAC learner) + `FastLearnerUpdater`
        (flat uniform replay buffer).
    (b) stock: RLlib 2.60's default SAC module (64x64) and learner + `StockLearnerUpdater` (prioritised
        episode replay buffer).

Success is the share of 50 fixed test episodes (20 steps each, deterministic squashed-mean actions)
that reach the goal; "untrained" is the same score of the freshly built module of that path and seed.
Both paths run with `--torch-threads` torch threads (default 1: what the suite's test ran with).

Usage (from the repository root):

    PYTHONPATH=. RAY_AUTH_MODE=disabled .venv/bin/python benchmarks/learning_parity.py \
        --seeds 0 1 --env-steps 10000

Prints one row per path and seed (untrained and trained success, whether the env runner holds the
learner's weights, wall time of the training), then per path the mean and min success and the mean
wall time, and as the last line `fast_minus_stock=<x>` (mean success, fast minus stock).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

import torch  # noqa: E402

from tests.test_gc_sac_learning import success_rate, train  # noqa: E402

PATHS = ("fast", "stock")


def run_one(path: str, seed: int, env_steps: int, torch_threads: int) -> dict[str, float]:
    torch.set_num_threads(torch_threads)
    untrained = success_rate(
        train(fast=path == "fast", env_steps=0, seed=seed, torch_threads=torch_threads)[0]
    )
    torch.set_num_threads(torch_threads)
    t0 = time.perf_counter()
    module, runner_module, _ = train(
        fast=path == "fast", env_steps=env_steps, seed=seed, torch_threads=torch_threads
    )
    seconds = time.perf_counter() - t0
    success = success_rate(module)
    synced = success_rate(runner_module) == success
    return {"untrained": untrained, "success": success, "synced": float(synced), "seconds": seconds}


def main(argv: list[str] | None = None) -> float:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--env-steps", type=int, default=10_000, help="env steps per run (one update per step)")
    p.add_argument("--paths", nargs="+", choices=PATHS, default=list(PATHS))
    p.add_argument("--torch-threads", type=int, default=1)
    args = p.parse_args(argv)

    print(
        f"env=ReachGoal2D env_steps={args.env_steps} seeds={args.seeds} paths={args.paths} "
        f"torch_threads={args.torch_threads} batch=64 hidden=[64, 64] learning_starts=500"
    )
    print(f"{'path':<6} {'seed':>4} {'untrained':>9} {'success':>7} {'synced':>6} {'wall s':>7}")
    rows: dict[str, list[dict[str, float]]] = {path: [] for path in args.paths}
    for seed in args.seeds:  # seeds outer, paths inner: load drift hits both paths alike
        for path in args.paths:
            r = run_one(path, seed, args.env_steps, args.torch_threads)
            rows[path].append(r)
            print(
                f"{path:<6} {seed:>4} {r['untrained']:>9.2f} {r['success']:>7.2f} "
                f"{'yes' if r['synced'] else 'NO':>6} {r['seconds']:>7.1f}",
                flush=True,
            )

    mean = {path: statistics.mean(r["success"] for r in rs) for path, rs in rows.items()}
    for path, rs in rows.items():
        print(
            f"{path}: success mean={mean[path]:.2f} min={min(r['success'] for r in rs):.2f}, "
            f"wall mean={statistics.mean(r['seconds'] for r in rs):.1f} s over {len(rs)} seed(s)"
        )
    if "fast" in rows and "stock" in rows:
        ratio = statistics.mean(r["seconds"] for r in rows["stock"]) / statistics.mean(
            r["seconds"] for r in rows["fast"]
        )
        print(f"wall time stock/fast: {ratio:.1f}x")
    diff = mean["fast"] - mean["stock"] if "fast" in mean and "stock" in mean else float("nan")
    print(f"fast_minus_stock={diff:.3f}")
    return diff


if __name__ == "__main__":
    main()
