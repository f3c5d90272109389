"""NEXT against RRT* on the maze agents: success, path length and collision checks per solved task.

    PYTHONPATH=. python benchmarks/next_planner.py [--agents point rigid snake] [--layout four-rooms]
        [--tasks 20] [--rrt-time-limit 3.0] [--seed 0] [--<setting> VALUE ...]

Per agent: RRT* (OMPL, `--rrt-time-limit` s per task, the sweep's reference) on the first `--tasks` test
tasks; then NEXT (copilot_ray.planning.next_planner) trained on the layout's training tasks as a sweep
trial of `algorithm: next` trains it (copilot_ray/algorithms/next/trial.py): imitation of `--num-demos`
demonstrations, then `--self-improve-rounds` rounds of its own searches, each followed by a search of the
same test tasks. Every setting of `algorithm: next` is a flag (`--step-length`, `--max-checks`,
`--max-iterations`, `--num-demos`, `--demo-time-s`, `--tasks-per-round`, `--hidden 128 128`, ...; their
defaults are the sweep's). Run it on the first 20 test tasks, then with `--tasks 100` for all of them.

Columns: solved share; mean path length over solved tasks (env distance) and the mean ratio to RRT*'s on
tasks both solved; the test-time collision checks per solved task (RRT*: all its checks over the tasks,
per task it solved; NEXT: its evaluation searches', likewise); the training checks (demonstrations and
self-improvement) and `paths/collision_checks_vs_rrt` as the sweep logs it (training + evaluation checks
over RRT*'s total on the same tasks).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from rrt_star import rrt_on_test_tasks  # noqa: E402 - benchmarks/rrt_star.py, next to this script

from copilot_ray import keys  # noqa: E402
from copilot_ray.algorithms.next.config import NEXTConfig  # noqa: E402
from copilot_ray.algorithms.next.settings import SETTINGS  # noqa: E402
from copilot_ray.planning.next_planner import (  # noqa: E402
    NEXTPlanner,
    padded_paths,
    rrt_star_demonstrations,
)
from copilot_ray.planning.path_metrics import RRTReference, path_metrics, score_paths  # noqa: E402
from copilot_ray.registry import RunContext  # noqa: E402
from copilot_ray.settings import problems  # noqa: E402

# Set by --tasks and --rrt-time-limit instead.
_NOT_FLAGS = ("eval_num_tasks", "rrt_reference_time_s")


def _add_setting_flags(parser: argparse.ArgumentParser) -> None:
    for key, s in SETTINGS.items():
        if key in _NOT_FLAGS:
            continue
        help_ = f"{s.doc} (default {s.default})"
        if s.kind == "bool":
            parser.add_argument(
                s.flag, dest=key, action=argparse.BooleanOptionalAction, default=None, help=help_
            )
        elif s.kind == "list":
            parser.add_argument(s.flag, dest=key, type=int, nargs="+", default=None, help=help_)
        elif s.kind == "str":
            parser.add_argument(s.flag, dest=key, choices=s.choices, default=None, help=help_)
        else:
            parser.add_argument(
                s.flag, dest=key, type=int if s.kind == "int" else float, default=None, help=help_
            )


def _evaluate(planner, maze, starts, goals, seed: int, round_: int):
    rng = np.random.default_rng([seed, round_, 7])  # as the trial: apart from the training stream
    results = [planner.search(s, g, rng=rng) for s, g in zip(starts, goals, strict=True)]
    return results, score_paths(maze, padded_paths(results), goals)


def _row(name, solved, length, ratio, checks_per_solved, training, vs_rrt, seconds) -> str:
    ratio_s = f"{ratio:.3f}" if np.isfinite(ratio) else "-"
    vs = f"{vs_rrt:.3f}" if np.isfinite(vs_rrt) else "-"
    return (
        f"  {name:<14} {solved:6.2f} {length:11.3f} {ratio_s:>8} {checks_per_solved:14,.0f} "
        f"{training:15,.0f} {vs:>9} {seconds:8.1f}"
    )


def run_agent(agent: str, args, values: dict) -> None:
    t0 = time.perf_counter()
    env, starts, goals, ref = rrt_on_test_tasks(
        agent, args.layout, args.tasks, args.rrt_time_limit, args.seed
    )
    maze = env.unwrapped
    reference = RRTReference.from_results(ref)
    rrt_s = time.perf_counter() - t0
    solved_n = max(1, int(reference.solved.sum()))
    print(f"\n{agent} on {args.layout}, {len(starts)} test tasks")
    print("  method         solved  mean length  / RRT*  checks/solved  training checks  total/RRT*   wall s")
    print(
        _row(
            f"RRT* {args.rrt_time_limit:g} s",
            reference.solved.mean(),
            reference.length[reference.solved].mean() if reference.solved.any() else float("nan"),
            1.0,
            reference.checks.sum() / solved_n,
            0,
            1.0,
            rrt_s,
        )
    )
    cfg = NEXTConfig.from_settings(
        values, RunContext(f"maze-{agent}", {"layout": args.layout}, seed=args.seed)
    )
    planner = NEXTPlanner.for_env(env, cfg.search_settings(), cfg.train_settings(), cfg.seed)
    train_starts, train_goals = (x.astype(np.float64) for x in maze.tasks("train"))
    t0 = time.perf_counter()
    for round_ in range(cfg.self_improve_rounds + 1):
        if round_ == 0:
            n = min(cfg.num_demos, len(train_starts))
            if cfg.demonstrator == "rrt_star":
                paths, checks = rrt_star_demonstrations(
                    env, train_starts[:n], train_goals[:n], cfg.demo_time_s, cfg.seed
                )
                planner.add_checks(checks)
            else:
                results = [
                    planner.search(s, g, guided=False, improve_iterations=cfg.train_improve_iterations)
                    for s, g in zip(train_starts[:n], train_goals[:n], strict=True)
                ]
                paths = [r.path if r.solved else None for r in results]
            planner.imitate(paths, train_goals[:n])
            planner.train(cfg.demo_train_steps)
            name = f"NEXT demos {n}"
        else:
            size = min(cfg.tasks_per_round, len(train_starts))
            idx = planner.rng.choice(len(train_starts), size=size, replace=False)
            planner.self_improve(
                train_starts[idx], train_goals[idx], cfg.round_train_steps, cfg.train_improve_iterations
            )
            name = f"NEXT round {round_}"
        if round_ < cfg.self_improve_rounds and not args.eval_every_round:
            continue
        training = planner.checks
        results, scores = _evaluate(planner, maze, starts, goals, cfg.seed, round_ + 1)
        planner.checks = training
        eval_checks = sum(r.checks for r in results)
        figures = path_metrics(scores, training + eval_checks, reference)
        print(
            _row(
                name,
                figures[keys.PATH_SUCCESS],
                figures[keys.PATH_LENGTH],
                figures[keys.PATH_LENGTH_VS_RRT],
                eval_checks / max(1, int(scores.success.sum())),
                training,
                figures[keys.PATH_CHECKS_VS_RRT],
                time.perf_counter() - t0,
            ),
            flush=True,
        )
    env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--agents", nargs="+", default=["point", "rigid", "snake"], choices=["point", "rigid", "snake"]
    )
    parser.add_argument("--layout", default="four-rooms")
    parser.add_argument("--tasks", type=int, default=20, help="test tasks scored (the first ones; 100: all)")
    parser.add_argument("--rrt-time-limit", type=float, default=3.0, help="RRT*'s seconds per test task")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--eval-every-round",
        action="store_true",
        help="search the test tasks after every round, not only the last",
    )
    _add_setting_flags(parser)
    args = parser.parse_args()
    values = {k: getattr(args, k) for k in SETTINGS if k not in _NOT_FLAGS and getattr(args, k) is not None}
    values["eval_num_tasks"] = args.tasks
    for key, value, why in problems(SETTINGS, values):
        parser.error(f"{SETTINGS[key].flag} {value!r}: {key} {why}")
    torch.set_num_threads(1)
    print("command: PYTHONPATH=. python " + shlex.join(sys.argv))
    effective = {k: values.get(k, s.default) for k, s in SETTINGS.items() if k not in _NOT_FLAGS}
    print("NEXT settings: " + ", ".join(f"{k}={v}" for k, v in effective.items()))
    for agent in args.agents:
        run_agent(agent, args, values)


if __name__ == "__main__":
    main()
