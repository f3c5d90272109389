"""Planner only: the paper's indicator collision cost against the graded length-in-collision cost.

No agent: the planner pi_p is trained with alpha = 1 (Euclidean segment cost plus the collision term)
on the maze's training tasks, as CO-PILOT's planner phase does before any time cost is learned, and
its deterministic (mean) trees on the held-out test tasks are scored on the geometry alone:

    collision_free  share of test tasks whose finest path (layer K) touches no obstacle
    length_ratio    finest path length / exact shortest collision-free path length, over the
                    collision-free plans (1.0 = optimal)

Usage (from the repository root):

    PYTHONPATH=. .venv/bin/python benchmarks/planner_collision.py --iterations 400 --seeds 0 1

Prints one line per evaluation and a table at the end; the last line is
`collision_free indicator=<x> length=<y>` (means over seeds at the last evaluation).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from copilot_ray.algorithms.copilot.config import DEFAULT_PLANNER, build_planner
from copilot_ray.envs import make
from copilot_ray.envs.maze.env import shortest_path_lengths
from copilot_ray.planning import SegmentCost, construct_trees
from copilot_ray.planning.subgoal_tree import layer_indices


def evaluate(planner, env, starts, goals, depth, shortest):
    trees = planner.sample(starts, goals, deterministic=True)
    path = trees[:, layer_indices(depth, depth)]
    a, b = path[:, :-1].reshape(-1, 2), path[:, 1:].reshape(-1, 2)
    free = ~env.segments_collide(a, b).reshape(len(trees), -1).any(axis=1)
    length = np.linalg.norm(np.diff(path, axis=1), axis=-1).sum(axis=1)
    ratio = float(np.mean(length[free] / shortest[free])) if free.any() else float("nan")
    return float(free.mean()), ratio


def run(collision_cost: str, seed: int, args, env, test, shortest) -> list[tuple[int, float, float, float]]:
    torch.manual_seed(seed)
    low, high = env.goal_space.low, env.goal_space.high
    # CO-PILOT's planner defaults (the gradient clip keeps PPO from diverging at K = 5).
    planner = build_planner(DEFAULT_PLANNER, env.goal_dim, args.depth, low, high, seed)
    cost = SegmentCost(
        alpha=1.0,
        segments_collide=env.segments_collide,
        collision_cost=collision_cost,
        collision_lengths=env.collision_lengths,
        # The defaults of CoPilotConfig.collision_penalty_value(): 10 per segment, 100 per unit length.
        collision_penalty=100.0 if collision_cost == "length" else 10.0,
    )
    train_starts, train_goals = env.tasks("train")
    rng = np.random.default_rng(seed)
    rows, t0 = [], time.perf_counter()
    for it in range(1, args.iterations + 1):
        idx = rng.choice(len(train_starts), size=args.task_batch_size, replace=False)
        construct_trees(
            planner,
            train_starts[idx],
            train_goals[idx],
            args.depth,
            cost,
            num_samples=args.num_samples,
            rng=rng,
        )
        if it % args.eval_every == 0 or it == args.iterations:
            free, ratio = evaluate(planner, env, *test, args.depth, shortest)
            rows.append((it, free, ratio, time.perf_counter() - t0))
            print(
                f"{collision_cost:9s} seed {seed} iter {it:4d}: collision_free {free:.2f} "
                f"length_ratio {ratio:.2f}  ({rows[-1][3]:.0f} s)",
                flush=True,
            )
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--depth", type=int, default=5, help="tree depth K")
    p.add_argument("--iterations", type=int, default=400, help="task mini-batches (planner phases)")
    p.add_argument("--task-batch-size", type=int, default=30)
    p.add_argument("--num-samples", type=int, default=16)
    p.add_argument("--eval-every", type=int, default=100)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    args = p.parse_args()
    torch.set_num_threads(args.threads)

    env = make("maze-point", layout=args.layout).unwrapped
    test = env.tasks("test")
    shortest = shortest_path_lengths(env, *test)
    print(
        f"layout={args.layout} K={args.depth} iterations={args.iterations} B={args.task_batch_size} "
        f"samples={args.num_samples} seeds={args.seeds} test tasks={len(test[0])}"
    )
    final: dict[str, list[tuple[float, float]]] = {}
    for collision_cost in ("indicator", "length"):
        for seed in args.seeds:
            rows = run(collision_cost, seed, args, env, test, shortest)
            final.setdefault(collision_cost, []).append(rows[-1][1:3])

    print("\n| collision_cost | seeds | collision-free plans (mean) | per seed | length / shortest |")
    print("|---|---|---|---|---|")
    means = {}
    for name, results in final.items():
        frees = [f for f, _ in results]
        ratios = [r for _, r in results if not np.isnan(r)]
        means[name] = statistics.fmean(frees)
        ratio = f"{statistics.fmean(ratios):.2f}" if ratios else "-"
        per_seed = ", ".join(f"{f:.2f}" for f in frees)
        print(f"| {name} | {len(results)} | {means[name]:.2f} | {per_seed} | {ratio} |")
    print(f"collision_free indicator={means['indicator']:.2f} length={means['length']:.2f}")


if __name__ == "__main__":
    main()
