"""One CO-PILOT run without Tune.

    python -m copilot_ray.train --env maze-point --layout four-rooms --tree-depth 5 --repetitions 5 \
        --stop-env-steps 200000 --seed 0 [--tracking-uri sqlite:///mlflow.db]

Every CO-PILOT setting is a flag (`--planner-std-final 0.015`, `--preset paper_literal`; values are
written as in a sweep spec, so `null`, `[64, 64]` and `1e-3` work); `--help` lists them with their
rules. Prints one progress line per iteration, writes a checkpoint at the end (and on Ctrl-C), and logs
to MLflow when a tracking URI is given. Bad arguments are reported before Ray starts (exit status 2).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

from copilot_ray import keys
from copilot_ray.algorithms.registry import RunContext, get_algorithm
from copilot_ray.envs import make
from copilot_ray.settings import problems
from copilot_ray.spec import load_yaml_value

ALGORITHM = "copilot"
# The flags of settings whose names changed, so that old command lines keep working.
_ALIASES = {"eval_num_tasks": ["--eval-tasks"]}


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m copilot_ray.train", description=__doc__.split("\n\n")[0])
    run = p.add_argument_group("the run")
    run.add_argument("--env", default="maze-point", help="goal-conditioned env id (see copilot_ray.envs)")
    run.add_argument("--layout", default=None, help="maze layout: a built-in name or a layout file")
    run.add_argument("--stop-env-steps", type=int, default=100_000, help="stop after this many env steps")
    run.add_argument("--stop-iters", type=int, default=None, help="stop after this many iterations")
    run.add_argument("--seed", type=int, default=0)
    run.add_argument(
        "--num-env-runners", type=int, default=0, help="remote env runners (0: sample on driver)"
    )
    run.add_argument("--checkpoint-dir", default="results/train", help="where checkpoints go")
    run.add_argument("--tracking-uri", default=None, help="MLflow tracking URI; none: no MLflow")
    run.add_argument("--experiment", default="copilot-train", help="MLflow experiment name")
    settings = p.add_argument_group("CO-PILOT settings (default: the setting's own; see the README's table)")
    for s in get_algorithm(ALGORITHM).settings.values():
        if s.on_cli:
            default = "null" if s.default is None else s.default
            settings.add_argument(
                s.flag,
                *_ALIASES.get(s.key, []),
                dest=f"setting:{s.key}",
                metavar="VALUE",
                default=None,
                type=_Value(s.key),
                help=f"{s.doc} ({s.rule}; default {default})".replace("%", "%%"),
            )
    return p.parse_args(argv)


class _Value:
    """argparse `type`: the text as a spec value (YAML), kept apart from "flag not given" (None)."""

    def __init__(self, key: str) -> None:
        self.key = key
        self.__name__ = key  # argparse names the type in its errors

    def __call__(self, text: str) -> Any:
        return _Given(load_yaml_value(text))


class _Given:
    def __init__(self, value: Any) -> None:
        self.value = value


def setting_values(args: argparse.Namespace) -> dict[str, Any]:
    """The settings given on the command line, as `{key: value}`."""
    prefix = "setting:"
    return {
        name[len(prefix) :]: v.value
        for name, v in vars(args).items()
        if name.startswith(prefix) and v is not None
    }


def build_config(args: argparse.Namespace):
    """Builds and validates the algorithm config; raises ValueError naming the bad flag and value."""
    entry = get_algorithm(ALGORITHM)
    values = setting_values(args)
    found = problems(entry.settings, values)
    found += [(involved[-1], value, why) for involved, value, why in entry.combination_problems(values)]
    if found:
        key, value, why = found[0]
        raise ValueError(f"{entry.settings[key].flag} {value!r} is invalid: {why}")
    env_config: dict[str, Any] = {}
    if args.layout is not None:
        env_config["layout"] = args.layout
    # Building the env once here turns a bad env id, layout or env_config into an error now.
    make(args.env, **env_config).close()
    run = RunContext(
        env_id=args.env,
        env_config=env_config,
        seed=args.seed,
        num_env_runners=args.num_env_runners,
        # Sampling (without runners) and the learner share this process: give it the cores the
        # runners leave free; CoPilotConfig sizes torch's thread pool from this.
        num_cpus_for_main_process=max(1, (os.cpu_count() or 1) - args.num_env_runners),
    )
    config = entry.build_config(values, run)
    config.copy(copy_frozen=False).validate()
    return config


def progress_line(result: dict[str, Any], started: float) -> str:
    steps = keys.result_value(result, keys.ENV_STEPS) or 0

    def fmt(key: str) -> str:
        v = keys.result_value(result, key)
        return f"{v:.2f}" if isinstance(v, float) else "  - "

    return (
        f"iter {result[keys.TRAINING_ITERATION]:4d}  env_steps {int(steps):9d}  "
        f"success planned {fmt(keys.SUCCESS_PLANNED)} direct {fmt(keys.SUCCESS_DIRECT)}  "
        f"alpha {fmt(keys.ALPHA)}  wall {time.time() - started:7.1f}s"
    )


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        config = build_config(args)
    except (ValueError, KeyError, FileNotFoundError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    import ray

    from copilot_ray.privileges import tag_value
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
            run_name=f"{args.env}-K{config.tree_depth}-b{config.repetitions}-s{args.seed}",
            tags={
                keys.ALGORITHM_TAG: ALGORITHM,
                keys.ENV_TAG: args.env,
                keys.K_TAG: str(config.tree_depth),
                keys.B_TAG: str(config.repetitions),
                keys.ALPHA_SCHEDULE_TAG: str(setting_values(args).get("alpha_schedule", "paper_per_task")),
                keys.PRESET_TAG: config.preset or "default",
                keys.PRIVILEGES_TAG: tag_value(get_algorithm(ALGORITHM).privileges(config.setting_values())),
                keys.SEED_TAG: str(args.seed),
                keys.GIT_COMMIT_TAG: git_commit(),
            },
        )
        run_args = {k: v for k, v in vars(args).items() if not k.startswith("setting:")}
        run.log_params(params_for_mlflow({**run_args, **config.setting_values()}))
    algo = config.build_algo()
    started = time.time()
    checkpoint_dir = Path(args.checkpoint_dir).resolve()
    status = "FINISHED"
    try:
        while True:
            result = algo.train()
            print(progress_line(result, started), flush=True)
            steps = int(keys.result_value(result, keys.ENV_STEPS) or 0)
            if run is not None:
                run.log_metrics(metrics_from_result(result), step=steps)
            if steps >= args.stop_env_steps:
                break
            if args.stop_iters is not None and result[keys.TRAINING_ITERATION] >= args.stop_iters:
                break
    except KeyboardInterrupt:
        status = "KILLED"
        print("interrupted: writing a checkpoint before exiting", file=sys.stderr)
    finally:
        algo.save_to_path(str(checkpoint_dir))
        print(f"checkpoint: {checkpoint_dir}")
        if run is not None:
            trees = Path(algo.logdir) / keys.TREES_DIR
            if trees.is_dir():
                run.log_artifacts(trees, keys.TREES_DIR)
            run.end(status)
        algo.stop()
        ray.shutdown()
    return 0 if status == "FINISHED" else 130


if __name__ == "__main__":
    raise SystemExit(main())
