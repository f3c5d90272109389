"""RRT* (OMPL) on the maze agents: solved share, path length, collision checks per test task.

    PYTHONPATH=. python benchmarks/rrt_star.py [--agents point rigid snake] [--layout four-rooms]
        [--tasks 100] [--time-limit 3.0]

Per agent, on the first `--tasks` test tasks of the layout, with the env's own validity and motion
checks: the share solved within the time limit (a collision-free path to within the success radius),
the mean path length in the env's distance (for the point mass also against the exact shortest path),
and the mean collision checks (state + motion callbacks) per task. The paper's Fig. 4b/4c normalise
the other planners by these figures.
"""

from __future__ import annotations

import argparse
import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from copilot_ray.envs import make  # noqa: E402
from copilot_ray.envs.maze import shortest_path_lengths  # noqa: E402
from copilot_ray.planning.rrt_star import rrt_star_for_env  # noqa: E402


def rrt_on_test_tasks(agent: str, layout: str, tasks: int, time_limit: float, seed: int):
    """(env, starts, goals, results): RRT* on the first `tasks` test tasks of `maze-<agent>`."""
    env = make(f"maze-{agent}", layout=layout)
    maze = env.unwrapped
    starts, goals = (x.astype(np.float64)[:tasks] for x in maze.tasks("test"))
    rrt = rrt_star_for_env(env, time_limit_s=time_limit, seed=seed)
    results = [rrt.plan(s, g, maze.success_radius) for s, g in zip(starts, goals, strict=True)]
    return env, starts, goals, results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--agents", nargs="+", default=["point", "rigid", "snake"], choices=["point", "rigid", "snake"]
    )
    parser.add_argument("--layout", default="four-rooms")
    parser.add_argument("--tasks", type=int, default=100)
    parser.add_argument("--time-limit", type=float, default=3.0, help="seconds per query")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"RRT* on {args.layout}, {args.tasks} test tasks, {args.time_limit:g} s per task")
    print("agent  solved  mean length  length / shortest  collision checks  s/task")
    for agent in args.agents:
        env, starts, goals, results = rrt_on_test_tasks(
            agent, args.layout, args.tasks, args.time_limit, args.seed
        )
        solved = np.array([r.solved for r in results])
        length = np.array([r.length for r in results])
        ratio = "-"
        if agent == "point":
            shortest = shortest_path_lengths(env, starts, goals)
            ratio = f"{np.mean(length[solved] / shortest[solved]):.3f}"
        print(
            f"{agent:5s}  {solved.mean():6.2f}  {length[solved].mean():11.3f}  {ratio:>17s}  "
            f"{np.mean([r.collision_checks for r in results]):16,.0f}  {np.mean([r.seconds for r in results]):6.2f}"
        )


if __name__ == "__main__":
    main()
