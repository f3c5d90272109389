"""The HIRO-style hierarchy (``algorithm: hrl``) learning the demo's open maze and four-rooms: test success
against env steps, one line per evaluation.

    PYTHONPATH=. .venv/bin/python benchmarks/hrl.py                       # both, their default budgets
    PYTHONPATH=. .venv/bin/python benchmarks/hrl.py --envs open --env-steps 4000 --seeds 0 1

open: the demo's open maze (no walls, speed 0.05, success radius 0.1, 40 steps per task), a sub-goal every
5 steps within +-0.25 of the width, small nets, 4 high-level updates per high-level transition (the
settings of tests/test_hrl.py); default budget 4k env steps (the demo's budget for the off-policy agents).
four-rooms: the default maze (speed 0.0025, 800 steps per task as the SAC baseline), HIRO's c = 10 and
sub-goals within +-0.05 of the width (twice what the agent covers in 10 steps), the SAC baseline's nets;
default budget 30k env steps. 50 test tasks each.

Measured on the open maze with tests/test_hrl.py's settings (4 tasks per batch, 40 test tasks), when the
suite still checked it: seed 0 at 0.00 / 0.15 / 0.73 / 1.00 test success after 0.6k / 1.2k / 1.8k / 2.4k
env steps, seeds 1-3 at 0.68-1.00 after 2.3-2.4k; uniformly random actions at both levels 0.08-0.13.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

from copilot_ray import keys  # noqa: E402

ENVS = {
    "open": (
        {"layout": "empty", "speed": 0.05, "success_radius": 0.1},
        {
            "tau_max": 40,
            "hrl.c": 5,
            "hrl.subgoal_range": 0.25,
            "low.hidden": [64, 64],
            "high.hidden": [64, 64],
            "high.updates_per_transition": 4.0,
            "env_steps_per_iteration": 500,
            "num_steps_sampled_before_learning_starts": 500,
        },
        4000,
    ),
    "four-rooms": (
        {"layout": "four-rooms"},
        {"hrl.c": 10, "hrl.subgoal_range": 0.05, "env_steps_per_iteration": 3200},
        30000,
    ),
}


def run(name: str, seed: int, env_steps: int | None) -> list[tuple[int, float, float]]:
    from copilot_ray.algorithms.hrl.algorithm import HRL
    from copilot_ray.algorithms.hrl.config import HRLConfig
    from copilot_ray.registry import RunContext

    env_config, values, budget = ENVS[name]
    budget = env_steps or budget
    cfg = HRLConfig.from_settings(
        {**values, "eval_num_tasks": 50}, RunContext("maze-point", env_config, seed=seed)
    )
    algo = HRL(cfg)
    curve, start = [], time.time()
    try:
        while algo.env_steps < budget:
            m = algo.train()
            if m[keys.EVAL_FRESH]:
                curve.append(
                    (
                        algo.env_steps,
                        m[keys.EVAL_SUCCESS],
                        m[keys.eval_by_action(keys.SUCCESS_DIRECT, "sampled")],
                    )
                )
                print(
                    f"{name:10s} seed {seed}  env_steps {algo.env_steps:6d}  success {m[keys.EVAL_SUCCESS]:.2f} "
                    f"(sampled {curve[-1][2]:.2f})  sub-goals reached {m['hrl/train/subgoal_reached']:.2f}  "
                    f"{time.time() - start:6.1f}s",
                    flush=True,
                )
    finally:
        algo.stop()
    return curve


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--envs", nargs="+", choices=list(ENVS), default=list(ENVS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--env-steps", type=int, default=None, help="budget per run (default: the env's)")
    args = parser.parse_args()
    finals = {}
    for name in args.envs:
        for seed in args.seeds:
            curve = run(name, seed, args.env_steps)
            finals[(name, seed)] = curve[-1] if curve else None
    print("\n| env | seed | env steps | test success (deterministic) | (sampled) |\n|---|---|---|---|---|")
    for (name, seed), last in finals.items():
        if last is not None:
            print(f"| {name} | {seed} | {last[0]} | {last[1]:.2f} | {last[2]:.2f} |")


if __name__ == "__main__":
    main()
