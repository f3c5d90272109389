"""One CO-PILOT run without Tune.

    python -m copilot_ray.train --env maze-point --layout four-rooms --tree-depth 5 --repetitions 5 \
        --stop-env-steps 200000 --seed 0

Every CO-PILOT setting is a flag (`--planner-std-final 0.015`, `--preset paper_literal`; values are
written as in a sweep spec, so `null`, `[64, 64]` and `1e-3` work); `--help` lists them with their
rules and defaults; `--check` prints the run's plan and the wall time to expect and starts nothing
(train_plan.py). Prints a first line at once, one progress line per iteration and, inside an
iteration, a line at least every 10 s (the planner's warm start, the traversal's env steps and SAC
updates, evaluations); Ray's, RLlib's and MLflow's notices go to `<checkpoint folder>.console.log`
(`--verbose` shows them). The run is tracked in MLflow (by default in the embedded store
results/train/mlflow.db; `--no-tracking` for none) and its checkpoint (at the end, on Ctrl-C and on
SIGTERM, which stop it alike: the MLflow run KILLED, exit status 130 / 143) goes to a folder of its own
named after the run; `--resume THAT_FOLDER` continues the run there, in the same MLflow run. A first
Ctrl-C or SIGTERM inside an iteration stops at the next boundary (a warm-start phase's end, a
repetition's, an evaluation's), so that the resumed run goes on as if never stopped; a second one stops
at once. Every bad argument is reported, each naming the flag and its value, before Ray starts (exit
status 2).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from copilot_ray import keys
from copilot_ray.commands import python_module, relative_path
from copilot_ray.console import quiet_console
from copilot_ray.envs import UnknownEnvError, make
from copilot_ray.heartbeat import Heartbeat, StopRequested, hide_progress, show_progress, watched
from copilot_ray.registry import RunContext, get_algorithm
from copilot_ray.settings import problems
from copilot_ray.store import (
    default_tracking_uri,
    tracking_uri_problem,
    ui_hint,
    unwritable,
    unwritable_store,
)
from copilot_ray.sweep_spec import load_yaml_value
from copilot_ray.sweep_spec.estimate import duration_text
from copilot_ray.train_plan import checkpoint_folder, expected_seconds, format_train_plan

ALGORITHM = "copilot"
# The flags of settings whose names changed, so that old command lines keep working.
_ALIASES = {"eval_num_tasks": ["--eval-tasks"]}


RESULTS = Path("results") / "train"  # the default store and the runs' checkpoint folders, under the cwd
RUN_FILE = "train_run.json"  # in the checkpoint folder: the run's flags, MLflow run and store (--resume)
# What --resume may be given with: the budget may grow; the rest is the run's own (RUN_FILE).
RESUME_FLAGS = ("--resume", "--stop-env-steps", "--stop-iters", "--verbose")
EXIT_INTERRUPTED, EXIT_TERMINATED = 130, 143  # Ctrl-C, SIGTERM (128 + the signal's number)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def example() -> str:
    """--help's closing example, naming this install's Python and MLflow (they run as printed)."""
    budget = 300_000
    run = python_module(
        "copilot_ray.train", "--layout", "four-rooms", "--preset", "paper_literal", "--stop-env-steps", budget
    )
    ui, then = ui_hint(default_tracking_uri(RESULTS), "<id>")
    seconds = expected_seconds(ALGORITHM, {"preset": "paper_literal"}, budget, None)
    took = (
        ""
        if seconds is None
        else f"about {duration_text(seconds)} with a core of its own, by --check's measured figures; "
    )
    return (
        f"example ({took}--check prints the plan and the time first; --help lists every setting):\n"
        f"  {run} --seed 1\n  {ui}\n"
        f"  ({then}: the runs, not the GenAI pages MLflow 3's UI opens on by default)"
    )


class _Parser(argparse.ArgumentParser):
    """argparse's parser, but a bad flag is one line (its usage lists ~60 flags): exit status 2."""

    def error(self, message: str):
        self.exit(2, f"error: {message}\n({self.prog} --help lists every flag)\n")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = _Parser(
        prog=python_module("copilot_ray.train"),
        usage="%(prog)s [--env ENV] [--layout LAYOUT] [--stop-env-steps N] [--seed S] [--SETTING VALUE ...]",
        description=__doc__.split("\n\n")[0],
        epilog=example(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
        allow_abbrev=False,  # --resume tells the flags given from the run's own by their full names
    )
    run = p.add_argument_group("the run")
    run.add_argument(
        "--env", default="maze-point", help="goal-conditioned env id (copilot_ray.envs; default maze-point)"
    )
    run.add_argument(
        "--layout", default=None, help="maze layout: a built-in name or a layout file (default four-rooms)"
    )
    run.add_argument(
        "--stop-env-steps", type=int, default=100_000, help="stop after this many env steps (default 100000)"
    )
    run.add_argument(
        "--stop-iters",
        type=int,
        default=None,
        help="stop after this many iterations (default: none; with --eval-every-env-steps an iteration "
        "also ends at the repetition past each evaluation point)",
    )
    run.add_argument("--seed", type=int, default=0, help="the run's seed (default 0)")
    run.add_argument(
        "--num-env-runners", type=int, default=0, help="remote env runners (default 0: sample on the driver)"
    )
    run.add_argument(
        "--checkpoint-dir",
        default=None,
        help=f"where the checkpoint goes (default: {RESULTS}/<run name>, a folder of its own per run)",
    )
    run.add_argument(
        "--tracking-uri",
        default=None,
        help=f"MLflow tracking URI (default: the embedded store sqlite:///$PWD/{RESULTS}/mlflow.db)",
    )
    run.add_argument("--no-tracking", action="store_true", help="log nothing to MLflow")
    run.add_argument(
        "--experiment", default="copilot-train", help="MLflow experiment (default copilot-train)"
    )
    run.add_argument(
        "--resume",
        metavar="CHECKPOINT_DIR",
        default=None,
        help="continue the run whose checkpoint folder this is, in its MLflow run, with the flags it began "
        "with (only --stop-env-steps and --stop-iters may be given with it, to go further)",
    )
    run.add_argument(
        "--check",
        action="store_true",
        help="check every flag, print the plan (settings, env steps per iteration, evaluations, the store "
        "and checkpoint folder) and the wall time to expect, and start nothing",
    )
    run.add_argument(
        "--verbose",
        action="store_true",
        help="show Ray's, RLlib's and MLflow's notices on the console (default: only in "
        "<checkpoint folder>.console.log)",
    )
    settings = p.add_argument_group("CO-PILOT settings (default: the setting's own; see docs/settings.md)")
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
        try:
            return _Given(load_yaml_value(text))
        except Exception as err:  # noqa: BLE001 - any YAML error is "not a value", said in one line
            first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
            raise argparse.ArgumentTypeError(f"{text!r} is invalid: not a value ({first})") from None


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


class ArgumentsError(ValueError):
    """Bad command-line arguments: every problem, one line each ("--flag value is invalid: why")."""

    def __init__(self, lines: list[str]):
        super().__init__("\n".join(lines))
        self.lines = lines


def run_problems(args: argparse.Namespace) -> list[str]:
    """The run's own flags out of range, each named with its value."""
    out = []
    for flag, value, ok, need in (
        ("--stop-env-steps", args.stop_env_steps, args.stop_env_steps >= 1, "an integer >= 1"),
        ("--stop-iters", args.stop_iters, args.stop_iters is None or args.stop_iters >= 1, "an integer >= 1"),
        ("--seed", args.seed, args.seed >= 0, "an integer >= 0"),
        ("--num-env-runners", args.num_env_runners, args.num_env_runners >= 0, "an integer >= 0"),
    ):
        if not ok:
            out.append(f"{flag} {value!r} is invalid: must be {need}")
    if args.tracking_uri is not None and (why := tracking_uri_problem(args.tracking_uri)) is not None:
        out.append(f"--tracking-uri {args.tracking_uri!r} is invalid: {why}")
    elif not args.no_tracking:
        # the run's store must be writable before Ray starts (the default one: under ./results/train)
        uri = args.tracking_uri or default_tracking_uri(RESULTS)
        if (why := unwritable_store(uri)) is not None:
            out.append(f"--tracking-uri {uri!r}{'' if args.tracking_uri else ' (default)'} is invalid: {why}")
    checkpoints = args.checkpoint_dir or RESULTS
    if (why := unwritable(checkpoints)) is not None:
        out.append(
            f"--checkpoint-dir {str(checkpoints)!r}{'' if args.checkpoint_dir else ' (default)'} is invalid: {why}"
        )
    return out


def build_config(args: argparse.Namespace):
    """Builds and validates the algorithm config; raises ArgumentsError naming every bad flag and value."""
    values, run = checked_run(args)
    config = get_algorithm(ALGORITHM).build_config(values, run)
    config.copy(copy_frozen=False).validate()
    return config


def checked_run(args: argparse.Namespace) -> tuple[dict[str, Any], RunContext]:
    """The settings given and the run's context, every flag checked (no RLlib import yet); raises
    ArgumentsError naming every bad flag and value."""
    entry = get_algorithm(ALGORITHM)
    values = setting_values(args)
    found = problems(entry.settings, values)
    found += [(involved[-1], value, why) for involved, value, why in entry.combination_problems(values)]
    lines = run_problems(args) + [
        f"{entry.settings[key].flag} {value!r} is invalid: {why}" for key, value, why in found
    ]
    env_config: dict[str, Any] = {}
    if args.layout is not None:
        env_config["layout"] = args.layout
    # Building the env once here turns a bad env id, layout or env_config into an error now.
    try:
        make(args.env, **env_config).close()
    except UnknownEnvError as err:
        lines.append(f"--env {args.env!r} is invalid: {err}")
    except (ValueError, OSError) as err:
        flag, value = ("--layout", args.layout) if args.layout is not None else ("--env", args.env)
        lines.append(f"{flag} {value!r} is invalid: {err}")
    if lines:
        raise ArgumentsError(lines)
    run = RunContext(
        env_id=args.env,
        env_config=env_config,
        seed=args.seed,
        num_env_runners=args.num_env_runners,
        # Sampling (without runners) and the learner share this process, on one torch thread: for these
        # small networks a second thread gains little on an idle machine and loses up to 10x when
        # anything else uses the cores (docs/measured.md, "OpenMP"). CoPilotConfig sizes torch's thread
        # pool from this.
        num_cpus_for_main_process=1,
        env_step_budget=args.stop_env_steps,
    )
    return values, run


def plan(args: argparse.Namespace, values: dict[str, Any]) -> str:
    """--check's plan of the run (train_plan.py), from the checked flags alone."""
    tracking = None
    if not args.no_tracking:
        uri = args.tracking_uri or default_tracking_uri(RESULTS)
        tracking = f"experiment {args.experiment!r} at {uri}"
    checkpoint = checkpoint_folder(ALGORITHM, args.checkpoint_dir, RESULTS, args.env, values, args.seed)
    return format_train_plan(
        ALGORITHM,
        args.env,
        args.layout,
        args.seed,
        values,
        args.stop_env_steps,
        args.stop_iters,
        tracking,
        checkpoint,
    )


def progress_line(result: dict[str, Any], started: float) -> str:
    steps = keys.result_value(result, keys.ENV_STEPS) or 0

    def fmt(key: str) -> str:
        v = keys.result_value(result, key)
        return f"{v:.2f}" if isinstance(v, float) else "  - "

    return (
        f"iter {result[keys.TRAINING_ITERATION]:4d}  env_steps {int(steps):9d}  "
        # the test tasks' (what a report of train's store shows), named so: a sweep's lines show validation
        f"test success planned {fmt(keys.SUCCESS_PLANNED)} direct {fmt(keys.SUCCESS_DIRECT)}  "
        f"alpha {fmt(keys.ALPHA)}  wall {time.time() - started:7.1f}s"
    )


def run_name(args: argparse.Namespace, config, results: Path = RESULTS) -> str:
    """What the run is called in MLflow and its checkpoint folder: env, K, b, seed and when it started,
    with a "+" for each run that already has that folder under `results` (two runs started in one second
    must not share a checkpoint)."""
    name = (
        f"{args.env}-K{config.tree_depth}-b{config.repetitions}-s{args.seed}-{time.strftime('%Y%m%d-%H%M%S')}"
    )
    while (results / name).exists():
        name += "+"
    return name


def resumed_args(args: argparse.Namespace, argv: list[str]) -> tuple[argparse.Namespace, dict[str, Any]]:
    """`--resume DIR`: the flags the run began with (DIR/RUN_FILE), its budget raised by the
    --stop-env-steps / --stop-iters given now, and what RUN_FILE says of its MLflow run."""
    folder = Path(args.resume).expanduser().absolute()
    saved_file = folder / RUN_FILE
    if not saved_file.is_file():
        raise ArgumentsError(
            [
                f"--resume {args.resume!r} is invalid: {saved_file} does not exist (give the folder a run "
                "of `train` wrote its checkpoint to)"
            ]  # fmt: skip
        )
    given = [token.split("=", 1)[0] for token in argv if token.startswith("--")]
    others = [flag for flag in given if flag not in RESUME_FLAGS]
    if others:
        raise ArgumentsError(
            [
                f"{others[0]} is invalid with --resume: the run keeps the flags it began with ({saved_file}); "
                "only --stop-env-steps and --stop-iters may be given, to go further"
            ]  # fmt: skip
        )
    saved = json.loads(saved_file.read_text())
    resumed = parse_args(saved["argv"])
    resumed.stop_env_steps = args.stop_env_steps if "--stop-env-steps" in given else saved["stop_env_steps"]
    resumed.stop_iters = args.stop_iters if "--stop-iters" in given else saved["stop_iters"]
    resumed.resume, resumed.verbose, resumed.argv = str(folder), args.verbose, saved["argv"]
    resumed.checkpoint_dir = str(folder)
    return resumed, saved


def first_line(args: argparse.Namespace, values: dict[str, Any]) -> str:
    """What the run is, said before the minute Ray and RLlib take to start."""
    layout = f" ({args.layout})" if args.layout else ""
    depth, b = values.get("tree_depth"), values.get("repetitions")
    shape = "".join(f" {name}={v}" for name, v in (("K", depth), ("b", b)) if v is not None)
    stop = f"{args.stop_env_steps:,} env steps" + (
        f" or {args.stop_iters} iterations" if args.stop_iters is not None else ""
    )
    what = "resuming" if args.resume else "training"
    return (
        f"train: {what} CO-PILOT{shape} on {args.env}{layout}, seed {args.seed}, until {stop}; "
        "starting Ray and building the algorithm"
    )


class Terminated(KeyboardInterrupt):
    """SIGTERM, handled as Ctrl-C is (a checkpoint, the MLflow run KILLED), with its own exit status."""


class _Stops:
    """Ctrl-C and SIGTERM in the main thread. Inside an iteration (`at_boundaries`) the first one asks
    the algorithm, through its heartbeat, to stop at its next boundary (the end of a warm-start phase, of
    a repetition, of an evaluation), where a checkpoint continues exactly; a second one stops at once.
    While an iteration's result is recorded (`held`) a stop waits for it, so that the checkpoint and
    MLflow agree. Elsewhere (Ray's start, the build) a stop raises at once. A stop is raised as
    KeyboardInterrupt, or Terminated for SIGTERM."""

    def __init__(self) -> None:
        self._mode = "at_once"
        self._heartbeat: Heartbeat | None = None
        self._pending: type[KeyboardInterrupt] | None = None

    def handle(self, signum, frame) -> None:
        stop = Terminated if signum == signal.SIGTERM else KeyboardInterrupt
        if self._mode == "held":
            self._pending = self._pending or stop
            return
        if self._mode == "boundary" and self._pending is None and self._heartbeat is not None:
            self._pending = stop
            why = "terminated (SIGTERM)" if stop is Terminated else "interrupted"
            again = "another SIGTERM" if stop is Terminated else "Ctrl-C again"
            # Said by the heartbeat's own thread: a signal handler must not write to a stream.
            self._heartbeat.request_stop(
                f"{why}: stopping at {self._heartbeat.boundary}, then writing a checkpoint ({again} to "
                "stop at once)"
            )
            return
        raise stop()

    @contextlib.contextmanager
    def at_boundaries(self, heartbeat: Heartbeat):
        """Around `algo.train()`: a first stop waits for the algorithm's next boundary (the iteration
        then ends there, or its warm start pauses: StopRequested, raised as the stop it stands for)."""
        self._mode, self._heartbeat = "boundary", heartbeat
        try:
            yield
        except StopRequested as paused:
            stop, self._pending = self._pending or KeyboardInterrupt, None
            raise stop(str(paused)) from None
        finally:
            self._mode = "at_once"

    @contextlib.contextmanager
    def held(self):
        self._mode = "held"
        try:
            yield
        finally:
            self._mode = "at_once"
            if self._pending is not None:
                stop, self._pending = self._pending, None
                raise stop()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    args.argv = argv  # what --resume starts from again
    saved = None
    try:
        if args.resume is not None:
            args, saved = resumed_args(args, argv)
        values, _ = checked_run(args)
    except ArgumentsError as err:
        for line in err.lines:
            print(f"error: {line}", file=sys.stderr)
        return 2
    if args.check:
        print(plan(args, values))
        return 0
    started = time.time()
    print(first_line(args, values), flush=True)
    console = quiet_console(args.verbose)
    show_progress(started=started)  # the algorithm's heartbeat lines on this console
    try:
        try:
            with ticking("loading RLlib and checking the algorithm's config"):  # ~15 s on two busy cores
                config = build_config(args)
        except (ValueError, KeyError, FileNotFoundError) as err:
            print(f"error: {err}", file=sys.stderr)
            return 2
        return _run(args, config, console, saved, started)
    finally:
        hide_progress()
        if console is not None:
            console.close()


def _run(args: argparse.Namespace, config, console, saved: dict[str, Any] | None, started: float) -> int:
    """Runs (or, with `saved`, resumes) the run until its budget, Ctrl-C or SIGTERM: the exit status."""
    import ray

    from copilot_ray.tracking import metrics_from_result

    name = saved["name"] if saved else run_name(args, config)
    checkpoint_dir = Path(args.checkpoint_dir or RESULTS / name).absolute()
    if console is not None:
        console.log_to(checkpoint_dir.parent / f"{checkpoint_dir.name}.console.log")
        print(f"Ray's, RLlib's and MLflow's notices: {relative_path(console.path)} (--verbose shows them)")
    if saved:
        tracking_uri = saved["tracking_uri"]
    else:
        tracking_uri = None if args.no_tracking else args.tracking_uri or default_tracking_uri(RESULTS)
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    own_ray = not ray.is_initialized()  # a test's session Ray is used as it is, and left running
    if own_ray:
        with ticking("starting Ray"):
            ray.init(
                address="local",  # our own Ray, never one that RAY_ADDRESS or `ray start` points at
                num_cpus=max(os.cpu_count() or 1, args.num_env_runners + 1),
                include_dashboard=False,
                log_to_driver=False,
            )
    run = _mlflow_run(args, config, name, tracking_uri, saved, checkpoint_dir)
    status, code = "FINISHED", 0
    algo = None
    main_thread = threading.current_thread() is threading.main_thread()
    # Ray's driver exits on SIGTERM (a crash dump, the run left FINISHED); stop as Ctrl-C does instead.
    stops = _Stops()
    previous = {sig: signal.signal(sig, stops.handle) for sig in STOP_SIGNALS} if main_thread else {}
    try:
        with ticking("building the algorithm (RLlib's env runner and learner)"):
            algo = config.build_algo()
        algo.log_to(checkpoint_dir)  # the planner's trees beside the run's checkpoint, not in ~/ray_results
        steps = 0
        if saved:
            with ticking(f"restoring the checkpoint {relative_path(checkpoint_dir)}"):
                algo.restore_from_path(str(checkpoint_dir))
            steps = algo._env_steps()  # noqa: SLF001 - the lifetime count the checkpoint holds
            print(
                f"resumed from {checkpoint_dir}: iteration {algo.iteration}, {steps:,} env steps", flush=True
            )
        while not _done(args, algo.iteration, steps):
            # watched: a line even when one planner phase outlasts the interval
            with watched(algo.heartbeat), stops.at_boundaries(algo.heartbeat):
                result = algo.train()
            with stops.held():  # the iteration the checkpoint will hold is logged whole
                steps = int(keys.result_value(result, keys.ENV_STEPS) or 0)
                if run is not None:
                    metrics = metrics_from_result(result)
                    metrics[keys.TRAINING_ITERATION] = float(result[keys.TRAINING_ITERATION])
                    run.log_metrics(metrics, step=steps)
                print(progress_line(result, started), flush=True)
    except KeyboardInterrupt as stop:
        status, code = "KILLED", EXIT_TERMINATED if isinstance(stop, Terminated) else EXIT_INTERRUPTED
        why = "terminated (SIGTERM)" if isinstance(stop, Terminated) else "interrupted"
        where = f"{stop}; " if str(stop) else ""  # a paused warm start says how far it got
        print(f"{why}: {where}writing a checkpoint before exiting", file=sys.stderr, flush=True)
    except BaseException:
        status = "FAILED"
        raise
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, signal.SIG_IGN)  # the checkpoint is written whole
        if algo is not None:
            algo.save_to_path(str(checkpoint_dir))
            _write_run_file(checkpoint_dir, args, name, tracking_uri, run)
            print(f"checkpoint: {checkpoint_dir}")
            if status != "FINISHED":
                print(
                    f"continue it with: {python_module('copilot_ray.train', '--resume', relative_path(checkpoint_dir))}"
                )
        if run is not None:
            trees = Path(algo.logdir) / keys.TREES_DIR if algo is not None else None
            if trees is not None and trees.is_dir():
                run.log_artifacts(trees, keys.TREES_DIR)
            run.end(status)
            command, *then = ui_hint(tracking_uri, run.run.info.experiment_id)
            print(f"compare runs: {command}")
            for line in then:
                print(f"  {line}")
        if algo is not None:
            algo.stop()
        if own_ray:
            ray.shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return code


def _mlflow_run(args: argparse.Namespace, config, name: str, tracking_uri, saved, checkpoint_dir: Path):
    """The run's MLflow run: reopened when resuming, else a new one with the run's tags and params; None
    without tracking."""
    from copilot_ray.privileges import tag_value
    from copilot_ray.tracking import MlflowRun, git_commit, params_for_mlflow

    if not tracking_uri:
        return None
    if saved:
        run = MlflowRun.reopen(tracking_uri, saved["run_id"])
        print(f"MLflow run {name} ({run.run_id}) in {tracking_uri}, resumed", flush=True)
        return run
    RESULTS.mkdir(parents=True, exist_ok=True)
    run = MlflowRun(
        tracking_uri,
        args.experiment,
        run_name=name,
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
    how = ("argv", "resume", "verbose")  # how it was started, not what it is
    run_args = {k: v for k, v in vars(args).items() if not k.startswith("setting:") and k not in how}
    settings = {**config.setting_values(), "preset": config.preset or "default"}
    run.log_params(params_for_mlflow({**run_args, **settings, "checkpoint_dir": str(checkpoint_dir)}))
    print(f"MLflow run {name} ({run.run_id}) in {tracking_uri}", flush=True)
    return run


def ticking(what: str):
    """A heartbeat line every few seconds while a blocking step that reports nothing (Ray's start,
    RLlib's build of the algorithm) runs."""
    return watched(Heartbeat(doing=f"{what}..."))


def _done(args: argparse.Namespace, iteration: int, steps: int) -> bool:
    return steps >= args.stop_env_steps or (args.stop_iters is not None and iteration >= args.stop_iters)


def _write_run_file(folder: Path, args: argparse.Namespace, name: str, tracking_uri, run) -> None:
    """What --resume reads: the flags the run began with, its budget now, its MLflow run and store."""
    record = {
        "argv": args.argv,
        "stop_env_steps": args.stop_env_steps,
        "stop_iters": args.stop_iters,
        "name": name,
        "tracking_uri": tracking_uri,
        "run_id": None if run is None else run.run_id,
    }
    (folder / RUN_FILE).write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    raise SystemExit(main())
