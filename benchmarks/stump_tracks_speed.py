"""Env steps per second of `walker-stumps` against Gymnasium's plain BipedalWalker-v3.

Random actions (the same sequence for both), resets included whenever an episode ends (a random walker
falls within ~100 steps, so resets are a fair share of the time for both). The two envs are timed in
turn, `--repeats` times, and the median of each is compared. Target: the stump tracks cost at most 20 %
more per step (ratio <= 1.2).

    .venv/bin/python benchmarks/stump_tracks_speed.py [--steps 5000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

from copilot_ray.envs import make

TARGET_RATIO = 1.2


def steps_per_second(env: gym.Env, actions: np.ndarray, seed: int) -> float:
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000, help="env steps per timing")
    parser.add_argument("--repeats", type=int, default=5, help="timings of each env, interleaved")
    parser.add_argument("--legs", default="default", choices=["short", "default", "long"])
    args = parser.parse_args()

    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 4)).astype(np.float32)
    plain = gym.make("BipedalWalker-v3")
    stumps = make("walker-stumps", legs=args.legs)  # tracks from the 50 training distributions
    rates: dict[str, list[float]] = {"BipedalWalker-v3": [], "walker-stumps": []}
    for r in range(args.repeats):
        rates["BipedalWalker-v3"].append(steps_per_second(plain, actions, seed=r))
        rates["walker-stumps"].append(steps_per_second(stumps, actions, seed=r))
    plain.close()
    stumps.close()

    median = {name: statistics.median(values) for name, values in rates.items()}
    for name, values in rates.items():
        print(f"{name:18s} median {median[name]:8.0f} steps/s   ({', '.join(f'{v:.0f}' for v in values)})")
    ratio = median["BipedalWalker-v3"] / median["walker-stumps"]
    verdict = "met" if ratio <= TARGET_RATIO else "NOT met"
    print(
        f"time per step, walker-stumps / BipedalWalker-v3: {ratio:.3f} (target <= {TARGET_RATIO}: {verdict})"
    )


if __name__ == "__main__":
    main()
