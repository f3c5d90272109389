"""Env steps per second of `ant-maze` against Gymnasium's raw `Ant-v5` and Gymnasium-Robotics' raw AntMaze.

    PYTHONPATH=. python benchmarks/ant_maze_speed.py [--steps 5000] [--repeats 5] [--map u-maze]

Random actions, one process, one thread; the three envs are timed in turn, `--repeats` times
(interleaved, so a busy machine slows all of them alike), and the median of each is printed with its
ratio to Ant-v5. Two costs are told apart: the maze's (AntMaze against Ant-v5: the wall boxes MuJoCo
checks for contacts every sub-step) and this project's wrapper (ant-maze against AntMaze: wall-contact
and flip checks, the observation dict, the sparse reward). The issue's target: the wrapper costs
<= 15 %.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import statistics
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from copilot_ray.envs import make  # noqa: E402
from copilot_ray.envs.ant_maze import MAPS  # noqa: E402

with contextlib.redirect_stderr(io.StringIO()):  # its import notice about unrelated envs
    import gymnasium_robotics  # noqa: E402


def steps_per_second(env: gym.Env, steps: int, seed: int) -> float:
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, (steps, env.action_space.shape[0])).astype(np.float32)
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--map", default="u-maze", choices=sorted(MAPS))
    args = parser.parse_args()
    gym.register_envs(gymnasium_robotics)
    envs = {
        "Ant-v5 (raw Gymnasium)": gym.make("Ant-v5").unwrapped,
        "AntMaze v5 (raw Gymnasium-Robotics)": gym.make(
            "AntMaze_UMaze-v5",
            maze_map=MAPS[args.map],
            continuing_task=False,
            include_cfrc_ext_in_observation=False,
        ).unwrapped,
        f"ant-maze ({args.map})": make("ant-maze", map=args.map, max_episode_steps=10**9),
    }
    rates: dict[str, list[float]] = {name: [] for name in envs}
    for r in range(args.repeats):
        for name, env in envs.items():
            rates[name].append(steps_per_second(env, args.steps, seed=r))
    base = statistics.median(rates["Ant-v5 (raw Gymnasium)"])
    maze = statistics.median(rates["AntMaze v5 (raw Gymnasium-Robotics)"])
    print(f"{'env':38s} {'steps/s (median)':>16s} {'x Ant-v5':>9s}   all repeats")
    for name, values in rates.items():
        med = statistics.median(values)
        print(f"{name:38s} {med:16,.0f} {med / base:9.3f}   {', '.join(f'{v:,.0f}' for v in values)}")
    ours = statistics.median(rates[f"ant-maze ({args.map})"])
    print(f"\nthe maze's cost (AntMaze vs Ant-v5):       {1 - maze / base:+.1%}")
    print(f"the wrapper's cost (ant-maze vs AntMaze):  {1 - ours / maze:+.1%}   (target <= 15 %)")
    print(f"all together (ant-maze vs Ant-v5):         {1 - ours / base:+.1%}")
    for env in envs.values():
        env.close()


if __name__ == "__main__":
    main()
