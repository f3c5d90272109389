"""maze-rigid and maze-snake figures per built-in layout: task length, motion-check speed, misses.

    PYTHONPATH=. python benchmarks/maze_bodies.py [--agents rigid snake] [--motions 20000] [--reference-motions 2000]

Per agent and layout, on the default test tasks: the mean shortest collision-free path of the body's
reference point (the stick's centre, the snake's base; the point maze's exact visibility graph: a lower
bound of the body's path) in steps at the default speed; motion checks per second on one core (one-step motions, random configurations); and
how many of `--reference-motions` random motions (one step to a planner's segment) the conservative
advancement reports free although a 2000-configuration reference finds a collision (must be 0), and
how many it reports colliding that the reference finds free (rechecked with 100,000 configurations).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from copilot_ray.envs import make  # noqa: E402
from copilot_ray.envs.maze import builtin_layout_names  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_maze_bodies import random_motions, reference_motion_collides  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", nargs="+", default=["rigid", "snake"], choices=["rigid", "snake"])
    parser.add_argument("--motions", type=int, default=20_000)
    parser.add_argument("--reference-motions", type=int, default=2_000)
    args = parser.parse_args()
    print("agent  layout       ref. path  >= steps  motions/s   missed  false alarms (confirmed by 100k)")
    for agent, layout in [(a, lay) for a in args.agents for lay in builtin_layout_names()]:
        env = make(f"maze-{agent}", layout=layout).unwrapped
        body, obstacles = env.agent_geometry, env.obstacles
        starts, goals = (x.astype(np.float64) for x in env.tasks("test"))
        centre = obstacles.visibility_graph.lengths(starts[:, :2], goals[:, :2])
        rng = np.random.default_rng(0)
        a, b = random_motions(rng, args.motions, body.speed, body.config_dim)
        t0 = time.perf_counter()
        body.motions_collide(obstacles, a, b)
        rate = args.motions / (time.perf_counter() - t0)
        missed = alarms = 0
        for scale in (0.003, 0.02, 0.1):
            a, b = random_motions(rng, args.reference_motions // 3, scale, body.config_dim)
            ours = body.motions_collide(obstacles, a, b)
            ref = reference_motion_collides(body, obstacles, a, b)
            missed += int((ref & ~ours).sum())
            doubt = np.flatnonzero(ours & ~ref)
            fine = reference_motion_collides(body, obstacles, a[doubt], b[doubt], samples=100_000)
            alarms += len(doubt) - int(fine.sum())
        print(
            f"{agent:5s}  {layout:11s}  {centre.mean():8.3f}  {centre.mean() / body.speed:8.0f}  {rate:9,.0f}  "
            f"{missed:7d}  {alarms:5d}"
        )


if __name__ == "__main__":
    main()
