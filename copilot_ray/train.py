"""One CO-PILOT run without Tune.

    python -m copilot_ray.train --env maze-point --layout four-rooms --tree-depth 5 --repetitions 5 \
        --stop-env-steps 200000 --seed 0 [--tracking-uri sqlite:///mlflow.db]

Prints one progress line per iteration, writes a checkpoint at the end (and on Ctrl-C), and logs to
MLflow when a tracking URI is given. Bad arguments are reported before Ray starts (exit status 2).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m copilot_ray.train", description=__doc__.split("\n\n")[0])
    p.add_argument("--env", default="maze-point", help="goal-conditioned env id (see copilot_ray.envs)")
    p.add_argument("--layout", default=None, help="maze layout: a built-in name or a layout file")
    p.add_argument(
        "--preset",
        default=None,
        help="readings of the paper's ambiguities, e.g. paper_literal (default: the measured defaults)",
    )
    p.add_argument("--tree-depth", type=int, default=5, help="K (the paper uses 5)")
    p.add_argument("--repetitions", type=int, default=5, help="b (the paper uses 5)")
    p.add_argument("--alpha-schedule", default="paper_per_task", help="preset name of the alpha schedule")
    p.add_argument("--tau-max", type=int, default=None, help="step budget of one sub-task (default 25)")
    p.add_argument(
        "--collision-cost",
        choices=["indicator", "length"],
        default="indicator",
        help="planner's collision term: per colliding segment (paper) or per length in collision (reference code)",
    )
    p.add_argument("--task-batch-size", type=int, default=30, help="tasks per training iteration")
    p.add_argument("--stop-env-steps", type=int, default=100_000, help="stop after this many env steps")
    p.add_argument("--stop-iters", type=int, default=None, help="stop after this many iterations")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--num-env-runners", type=int, default=0, help="remote env runners (0: sample on driver)")
    p.add_argument("--eval-interval", type=int, default=1, help="iterations between evaluations (0: never)")
    p.add_argument("--eval-tasks", type=int, default=100, help="held-out test tasks per evaluation")
    p.add_argument(
        "--updates-per-env-step",
        type=float,
        default=None,
        help="SAC gradient steps per env step (default 1.0)",
    )
    p.add_argument("--stock-learner", action="store_true", help="RLlib's stock SAC learner path (slow)")
    p.add_argument("--checkpoint-dir", default="results/train", help="where checkpoints go")
    p.add_argument("--tracking-uri", default=None, help="MLflow tracking URI; none: no MLflow")
    p.add_argument("--experiment", default="copilot-train", help="MLflow experiment name")
    return p.parse_args(argv)


def build_config(args: argparse.Namespace):
    """Builds and validates the CoPilotConfig; raises ValueError naming the bad value."""
    from copilot_ray.algorithms.copilot import CoPilotConfig
    from copilot_ray.envs import make

    env_config: dict[str, Any] = {}
    if args.layout is not None:
        env_config["layout"] = args.layout
    # Building the env once here turns a bad env id, layout or env_config into an error now.
    make(args.env, **env_config).close()
    config = (
        CoPilotConfig()
        .environment(args.env, env_config=env_config)
        .env_runners(num_env_runners=args.num_env_runners)
        # Sampling (without runners) and the learner share this process: give it the cores the
        # runners leave free; CoPilotConfig sizes torch's thread pool from this.
        .resources(num_cpus_for_main_process=max(1, (os.cpu_count() or 1) - args.num_env_runners))
        .debugging(seed=args.seed)
    )
    if args.preset is not None:
        config.copilot(preset=args.preset)
    if args.tau_max is not None:
        config.copilot(tau_max=args.tau_max)
    config.copilot(
        tree_depth=args.tree_depth,
        repetitions=args.repetitions,
        alpha_schedule=args.alpha_schedule,
        collision_cost=args.collision_cost,
        task_batch_size=args.task_batch_size,
        eval_interval=args.eval_interval,
        eval_num_tasks=args.eval_tasks,
        updates_per_env_step=args.updates_per_env_step,
        fast_learner=not args.stock_learner,
    )
    config.copy(copy_frozen=False).validate()
    return config


def progress_line(result: dict[str, Any], started: float) -> str:
    cop = result.get("copilot", {})
    ev = cop.get("eval", {})
    steps = result.get("env_runners", {}).get("num_env_steps_sampled_lifetime", 0)

    def fmt(v):
        return f"{v:.2f}" if isinstance(v, float) else "  - "

    return (
        f"iter {result['training_iteration']:4d}  env_steps {int(steps):9d}  "
        f"success planned {fmt(ev.get('success_planned'))} direct {fmt(ev.get('success_direct'))}  "
        f"alpha {fmt(cop.get('alpha'))}  wall {time.time() - started:7.1f}s"
    )


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        config = build_config(args)
    except (ValueError, KeyError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    import ray

    from copilot_ray.tracking import MlflowRun, git_commit, metrics_from_result, params_for_mlflow

    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    ray.init(
        num_cpus=max(os.cpu_count() or 1, args.num_env_runners + 1),
        include_dashboard=False,
        log_to_driver=False,
    )
    run = None
    if args.tracking_uri:
        run = MlflowRun(
            args.tracking_uri,
            args.experiment,
            run_name=f"{args.env}-K{args.tree_depth}-b{args.repetitions}-s{args.seed}",
            tags={
                "algorithm": "copilot",
                "env": args.env,
                "K": str(args.tree_depth),
                "b": str(args.repetitions),
                "alpha_schedule": args.alpha_schedule,
                "preset": args.preset or "default",
                "seed": str(args.seed),
                "git_commit": git_commit(),
            },
        )
        run.log_params(params_for_mlflow(vars(args)))
    algo = config.build_algo()
    started = time.time()
    checkpoint_dir = Path(args.checkpoint_dir).resolve()
    status = "FINISHED"
    try:
        while True:
            result = algo.train()
            print(progress_line(result, started), flush=True)
            steps = int(result.get("env_runners", {}).get("num_env_steps_sampled_lifetime", 0))
            if run is not None:
                run.log_metrics(metrics_from_result(result), step=steps)
            if steps >= args.stop_env_steps:
                break
            if args.stop_iters is not None and result["training_iteration"] >= args.stop_iters:
                break
    except KeyboardInterrupt:
        status = "KILLED"
        print("interrupted: writing a checkpoint before exiting", file=sys.stderr)
    finally:
        algo.save_to_path(str(checkpoint_dir))
        print(f"checkpoint: {checkpoint_dir}")
        if run is not None:
            trees = Path(algo.logdir) / "copilot_trees"
            if trees.is_dir():
                run.log_artifacts(trees, "copilot_trees")
            run.end(status)
        algo.stop()
        ray.shutdown()
    return 0 if status == "FINISHED" else 130


if __name__ == "__main__":
    raise SystemExit(main())
