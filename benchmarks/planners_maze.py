"""Planners on the maze agents (the paper's Fig. 4b/4c in numbers): SGT-PG against RRT*.

    PYTHONPATH=. python benchmarks/planners_maze.py [--agents point rigid snake] [--layout four-rooms]
        [--phases 400] [--eval-every 100] [--tasks 20] [--rrt-time-limit 3.0] [--depth 5]
        [--angles raw|wrapped|scaled]

SGT-PG is the sub-goal-tree planner pi_p (copilot_ray.planning, the reference code's settings: constant
std 0.05, K = 5) trained alone on the fixed Euclidean + collision cost (alpha = 1, no agent, 30 training
tasks x 16 samples per phase), as in its paper. Every `--eval-every` phases its mean tree on the first
`--tasks` test tasks is scored as a motion plan: success = every finest segment collision-free (the path
ends at the goal itself), path length in the env's distance, and the collision checks spent so far in
training; RRT* (OMPL, `--rrt-time-limit` s per task) on the same tasks gives the reference figures, and
the normalised columns divide by them (length: on tasks both solved; checks: SGT-PG's training total
against RRT*'s total over the evaluated tasks).
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from rrt_star import rrt_on_test_tasks  # noqa: E402 - benchmarks/rrt_star.py, next to this script

from copilot_ray.algorithms.copilot.settings import PRESETS, defaults  # noqa: E402
from copilot_ray.planning import SegmentCost, SubgoalPlanner, construct_trees  # noqa: E402
from copilot_ray.planning.path_metrics import CountedChecks, score_paths  # noqa: E402
from copilot_ray.planning.subgoal_tree import layer_indices  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--agents", nargs="+", default=["point", "rigid", "snake"], choices=["point", "rigid", "snake"]
    )
    parser.add_argument("--layout", default="four-rooms")
    parser.add_argument("--phases", type=int, default=400)
    parser.add_argument("--eval-every", type=int, default=100)
    parser.add_argument("--tasks", type=int, default=20, help="test tasks scored")
    parser.add_argument("--rrt-time-limit", type=float, default=3.0)
    parser.add_argument("--depth", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--angles",
        choices=["raw", "wrapped", "scaled"],
        default="scaled",
        help="raw: angles as plain coordinates (mean midpoint, clipped); wrapped: short-way midpoints and "
        "wrapped samples; scaled: wrapped + the std of each dim divided by its distance weight",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    planner_settings = {**defaults("planner"), **PRESETS["paper_literal"]["planner"]}
    for agent in args.agents:
        env, starts, goals, ref = rrt_on_test_tasks(
            agent, args.layout, args.tasks, args.rrt_time_limit, args.seed
        )
        maze = env.unwrapped
        rrt_solved = np.array([r.solved for r in ref])
        rrt_length = np.array([r.length for r in ref])
        rrt_checks = sum(r.collision_checks for r in ref)
        print(
            f"\n{agent} on {args.layout}: RRT* solved {rrt_solved.mean():.2f}, mean length "
            f"{rrt_length[rrt_solved].mean():.3f}, {rrt_checks / len(ref):,.0f} checks per task"
        )
        print("  SGT-PG phase  solved  length / RRT*  training checks / RRT*'s  wall s")
        torch.manual_seed(args.seed)
        low, high = maze.goal_space.low, maze.goal_space.high
        planner = SubgoalPlanner.from_settings(
            {**planner_settings, "angles": args.angles},
            maze.goal_dim,
            args.depth,
            low,
            high,
            args.seed,
            geometry=maze.agent_geometry,
        )
        checks = CountedChecks(maze.segments_collide)
        cost = SegmentCost(
            alpha=1.0, segments_collide=checks, distance=maze.goal_distance, collision_penalty=10.0
        )
        train_starts, train_goals = maze.tasks("train")
        rng = np.random.default_rng(args.seed)
        t0 = time.perf_counter()
        for phase in range(1, args.phases + 1):
            idx = rng.choice(len(train_starts), size=30, replace=False)
            construct_trees(
                planner, train_starts[idx], train_goals[idx], args.depth, cost, num_samples=16, rng=rng
            )
            if phase % args.eval_every and phase != args.phases:
                continue
            trees = planner.sample(starts, goals, deterministic=True)
            scores = score_paths(maze, trees[:, layer_indices(args.depth, args.depth)], goals)
            free, length = scores.success, scores.length
            both = free & rrt_solved
            ratio = float(np.mean(length[both] / rrt_length[both])) if both.any() else float("nan")
            print(
                f"  {phase:12d}  {free.mean():6.2f}  {ratio:13.2f}  {checks.count / rrt_checks:23.1f}  "
                f"{time.perf_counter() - t0:6.0f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
