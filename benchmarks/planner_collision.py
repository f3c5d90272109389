"""Planner only: collision costs (the paper's indicator, the graded length-in-collision cost), the
planner's exploration std (constant, as the reference code, or annealed), its KL guard (`--max-kl`) and
a mean kept inside the goal box (`--mean squashed`).

No agent: the planner pi_p is trained with alpha = 1 (Euclidean segment cost plus the collision term)
on the maze's training tasks, as CO-PILOT's planner warm start does before any time cost is learned,
and its deterministic (mean) trees on the maze's VALIDATION tasks are scored (a probe chooses defaults,
so it never reads the test tasks):

    collision_free  share of validation tasks whose finest path (layer K) touches no obstacle
    length_ratio    finest path length / exact shortest collision-free path length, over the
                    collision-free plans (1.0 = optimal)
    oracle_follow   share of validation tasks an oracle agent (heads straight for each sub-goal at full
                    speed) completes following the finest path with --tau-max steps per sub-goal and
                    no collision: what a perfect agent could get out of these plans
    kl_max          the largest approximate KL of one layer's update since the last evaluation (the
                    collapse shows as 1e2 and more; see README, Known limits)

Usage (from the repository root):

    PYTHONPATH=. .venv/bin/python benchmarks/planner_collision.py --iterations 400 --seeds 0 1
    # CO-PILOT's default warm start (1000 phases, std 0.05 -> 0.015 over them), one JSON line per evaluation:
    PYTHONPATH=. .venv/bin/python benchmarks/planner_collision.py --collision-costs indicator \
        --iterations 1000 --std-final 0.015 --anneal-phases 1000 --layout u-maze --seeds 0 --log probe.jsonl
    PYTHONPATH=. .venv/bin/python benchmarks/planner_collision.py --summarise probe.jsonl [more.jsonl ...]

Prints one line per evaluation and a table at the end; the last line is
`collision_free <cost>=<x> ...` (means over seeds at the last evaluation). `--summarise` prints the
table of logged runs (several processes' logs together), one row per layout and variant.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections import defaultdict

import numpy as np
import torch

from copilot_ray.algorithms.copilot.settings import defaults
from copilot_ray.envs import make
from copilot_ray.envs.maze.env import shortest_path_lengths
from copilot_ray.evaluation import follow_waypoints
from copilot_ray.planning import SegmentCost, SubgoalPlanner, construct_trees
from copilot_ray.planning.planner import MEAN_MODES
from copilot_ray.planning.subgoal_tree import layer_indices

PLANNER = defaults("planner")  # CO-PILOT's planner settings


def oracle_policy(speed: float):
    """Heads straight for the sub-goal (obs = [position, sub-goal]), never overshooting it."""

    def act(obs: np.ndarray) -> np.ndarray:
        d = obs[:, 2:4] - obs[:, :2]
        n = np.linalg.norm(d, axis=1, keepdims=True)
        return d / np.maximum(n, 1e-12) * np.minimum(1.0, n / speed)

    return act


def evaluate(planner, env, starts, goals, depth, shortest, envs, tau_max):
    trees = planner.sample(starts, goals, deterministic=True)
    path = trees[:, layer_indices(depth, depth)]
    a, b = path[:, :-1].reshape(-1, 2), path[:, 1:].reshape(-1, 2)
    free = ~env.segments_collide(a, b).reshape(len(trees), -1).any(axis=1)
    length = np.linalg.norm(np.diff(path, axis=1), axis=-1).sum(axis=1)
    ratio = float(np.mean(length[free] / shortest[free])) if free.any() else float("nan")
    follow = follow_waypoints(envs, oracle_policy(env.nominal_step_distance), path, tau_max)
    return float(free.mean()), ratio, float(follow.success.mean())


def variant(collision_cost: str, args) -> str:
    """The row a run belongs to: its collision cost, std schedule and KL guard."""
    std = "constant" if args.std_final is None else f"{PLANNER['std']}->{args.std_final}/{args.anneal_phases}"
    mean = "" if args.mean == "free" else f" mean {args.mean}"
    return f"{collision_cost} std {std} max_kl {args.max_kl}{mean}"


def run(collision_cost: str, seed: int, args, env, held_out, shortest, envs) -> list[tuple]:
    torch.manual_seed(seed)
    low, high = env.goal_space.low, env.goal_space.high
    # CO-PILOT's planner defaults (the gradient clip keeps PPO from diverging at K = 5).
    settings = {**PLANNER, "max_kl": args.max_kl, "mean": args.mean}
    planner = SubgoalPlanner.from_settings(settings, env.goal_dim, args.depth, low, high, seed)
    std0 = float(PLANNER["std"])
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
    rows, t0, kl_max, rolled_back = [], time.perf_counter(), 0.0, 0
    for it in range(1, args.iterations + 1):
        if args.std_final is not None:  # CO-PILOT's annealing: linear over the first anneal_phases phases
            frac = min(1.0, (it - 1) / args.anneal_phases)
            planner.set_std(std0 + frac * (args.std_final - std0))
        idx = rng.choice(len(train_starts), size=args.task_batch_size, replace=False)
        stats = construct_trees(
            planner,
            train_starts[idx],
            train_goals[idx],
            args.depth,
            cost,
            num_samples=args.num_samples,
            rng=rng,
        ).stats
        kl_max = max(kl_max, *(stats[f"approx_kl_layer_{k}"] for k in range(1, args.depth + 1)))
        rolled_back += int(stats.get("rolled_back", 0))
        if it % args.eval_every == 0 or it == args.iterations:
            free, ratio, follow = evaluate(planner, env, *held_out, args.depth, shortest, envs, args.tau_max)
            rows.append((it, free, ratio, follow, time.perf_counter() - t0))
            print(
                f"{collision_cost:9s} seed {seed} iter {it:4d}: collision_free {free:.2f} "
                f"length_ratio {ratio:.2f} oracle_follow {follow:.2f} kl_max {kl_max:.3g} "
                f"rolled_back {rolled_back}  ({rows[-1][4]:.0f} s)",
                flush=True,
            )
            if args.log:
                record = {
                    "layout": args.layout,
                    "variant": variant(collision_cost, args),
                    "seed": seed,
                    "phase": it,
                    "collision_free": free,
                    "length_ratio": None if np.isnan(ratio) else ratio,
                    "oracle_follow": follow,
                    "kl_max": kl_max,
                    "rolled_back": rolled_back,
                    "seconds": rows[-1][4],
                }
                with open(args.log, "a") as log:
                    log.write(json.dumps(record) + "\n")
            kl_max, rolled_back = 0.0, 0
    return rows


def summarise(paths: list[str]) -> None:
    """One row per layout and variant: the last evaluation of each seed, and how many seeds collapsed
    (an update's approximate KL above 100 at any evaluation window)."""
    runs: dict[tuple, list[dict]] = defaultdict(list)
    for path in paths:
        with open(path) as f:
            for line in f:
                r = json.loads(line)
                runs[(r["layout"], r["variant"], r["seed"])].append(r)
    rows: dict[tuple, list[tuple[int, dict, bool]]] = defaultdict(list)
    for (layout, name, seed), records in sorted(runs.items()):
        records.sort(key=lambda r: r["phase"])
        collapsed = any(r["kl_max"] > 100 for r in records)
        rows[(layout, name)].append((seed, records[-1], collapsed))
    print("| layout | variant | seeds | phases | collision-free validation plans (mean) | per seed | "
          "oracle follows (mean) | seeds with KL > 100 |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for (layout, name), seeds in rows.items():
        frees = [last["collision_free"] for _, last, _ in seeds]
        per_seed = ", ".join(f"s{seed} {last['collision_free']:.2f}" for seed, last, _ in seeds)
        phases = "/".join(sorted({str(last["phase"]) for _, last, _ in seeds}))
        follow = statistics.fmean(last["oracle_follow"] for _, last, _ in seeds)
        collapsed = sum(c for _, _, c in seeds)
        print(
            f"| {layout} | {name} | {len(seeds)} | {phases} | {statistics.fmean(frees):.2f} | {per_seed} | "
            f"{follow:.2f} | {collapsed} |"
        )


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
    p.add_argument("--collision-costs", nargs="+", default=["indicator", "length"])
    p.add_argument(
        "--std-final", type=float, default=None, help="anneal the planner std to this (default: off)"
    )
    p.add_argument("--anneal-phases", type=int, default=1000, help="phases over which the std is annealed")
    p.add_argument("--tau-max", type=int, default=25, help="oracle's steps per sub-goal")
    p.add_argument(
        "--max-kl",
        type=float,
        default=PLANNER["max_kl"],
        help="undo updates whose KL exceeds this (default off)",
    )
    p.add_argument("--mean", choices=MEAN_MODES, default=PLANNER["mean"], help="pi_p's mean (planner.mean)")
    p.add_argument("--log", help="append one JSON line per evaluation to this file")
    p.add_argument("--summarise", nargs="+", metavar="LOG", help="print the table of these logs and exit")
    args = p.parse_args()
    if args.summarise:
        summarise(args.summarise)
        return
    torch.set_num_threads(args.threads)

    env = make("maze-point", layout=args.layout).unwrapped
    held_out = env.tasks("validation")
    shortest = shortest_path_lengths(env, *held_out)
    anneal = (
        "constant"
        if args.std_final is None
        else f"{PLANNER['std']} -> {args.std_final} over {args.anneal_phases}"
    )
    print(
        f"layout={args.layout} K={args.depth} iterations={args.iterations} B={args.task_batch_size} "
        f"samples={args.num_samples} seeds={args.seeds} validation tasks={len(held_out[0])} std {anneal} "
        f"max_kl={args.max_kl}"
    )
    envs = [make("maze-point", layout=args.layout) for _ in range(len(held_out[0]))]
    final: dict[str, list[tuple[float, float, float]]] = {}
    for collision_cost in args.collision_costs:
        for seed in args.seeds:
            rows = run(collision_cost, seed, args, env, held_out, shortest, envs)
            final.setdefault(collision_cost, []).append(rows[-1][1:4])

    print(
        "\n| collision_cost | seeds | collision-free validation plans (mean) | per seed | length / shortest | "
        "oracle follows |"
    )
    print("|---|---|---|---|---|---|")
    means = {}
    for name, results in final.items():
        frees = [f for f, _, _ in results]
        ratios = [r for _, r, _ in results if not np.isnan(r)]
        means[name] = statistics.fmean(frees)
        ratio = f"{statistics.fmean(ratios):.2f}" if ratios else "-"
        per_seed = ", ".join(f"{f:.2f}" for f in frees)
        follow = statistics.fmean(o for _, _, o in results)
        print(f"| {name} | {len(results)} | {means[name]:.2f} | {per_seed} | {ratio} | {follow:.2f} |")
    print("collision_free " + " ".join(f"{name}={value:.2f}" for name, value in means.items()))


if __name__ == "__main__":
    main()
