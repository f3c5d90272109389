"""Maze geometry figures for every built-in layout (and a few random mazes).

    PYTHONPATH=. python benchmarks/maze_geometry.py [--random-seeds 0 1 2] [--segments 200000]

Per layout, on the default test tasks: mean exact shortest path length, mean minimum steps at the
default speed (ceil((length - success_radius) / speed): the agent must enter the goal ball), the
fraction of straight start->goal segments that collide, and `segments_collide` throughput on one core.
"""

from __future__ import annotations

import argparse
import os
import time

# One core: the figure is the single-core throughput the brief asks for.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from copilot_ray.envs import make  # noqa: E402
from copilot_ray.envs.maze import DEFAULT_LAYOUT, builtin_layout_names, shortest_path_lengths  # noqa: E402


def throughput(env, n: int, repeats: int = 3) -> float:
    rng = np.random.default_rng(0)
    a, b = rng.random((n, 2)), rng.random((n, 2))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        env.unwrapped.segments_collide(a, b)
        best = min(best, time.perf_counter() - t0)
    return n / best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random-seeds", type=int, nargs="*", default=[0, 1, 2])
    parser.add_argument("--segments", type=int, default=200_000)
    args = parser.parse_args()
    names = builtin_layout_names() + [f"random15-{s}" for s in args.random_seeds]
    header = f"{'layout':<14}{'grid':>7}{'boxes':>6}{'mean_len':>10}{'max_len':>9}{'mean_steps':>11}{'max_steps':>10}{'straight_collide':>17}{'seg/s':>12}"
    print(header)
    for name in names:
        env = make("maze-point", layout=name)
        maze = env.unwrapped
        starts, goals = maze.tasks("test")
        lengths = shortest_path_lengths(env, starts, goals)
        steps = np.ceil(np.maximum(lengths - maze.success_radius, 0.0) / maze.nominal_step_distance)
        collide = maze.segments_collide(starts, goals).mean()
        rows, cols = maze.layout.shape
        mark = " (default)" if name == DEFAULT_LAYOUT else ""
        print(
            f"{name:<14}{f'{rows}x{cols}':>7}{len(maze.obstacles):>6}{lengths.mean():>10.3f}{lengths.max():>9.3f}"
            f"{steps.mean():>11.1f}{steps.max():>10.0f}{collide:>17.2f}{throughput(env, args.segments):>12,.0f}{mark}"
        )
    print(
        f"speed (nominal_step_distance) = {maze.nominal_step_distance}, success_radius = {maze.success_radius}"
    )


if __name__ == "__main__":
    main()
