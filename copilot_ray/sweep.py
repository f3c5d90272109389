"""Run a sweep spec on Ray Tune, tracked in MLflow.

    python -m copilot_ray.sweep SPEC.yaml [--check] [--resume] [--address ADDR] [--tracking-uri URI]

* The spec is validated first (``copilot_ray.sweep_spec.load_specs``): a bad spec prints one line per problem
  (file, key path, value, why) on stderr and exits 2 before Ray is imported. A file of several specs
  (YAML documents, e.g. one per algorithm) is validated whole, then its parts run one after another. ``--check`` prints the plan
  (configurations x seeds, trials, budget) and exits 0, also without Ray.
* Running: a local Ray with ``os.cpu_count()`` CPUs, or the cluster at ``--address``. Everything lands in
  ``<tracking.storage>/<name>/``: ``spec.yaml`` (the spec as resolved: absolute paths; trials and
  ``--resume`` read this copy), ``tune/<experiment>/`` (Tune's state, trial folders, checkpoints),
  ``mlflow.db`` + ``mlartifacts/`` (the default MLflow store) and, for optuna, ``optuna.db`` (the
  studies). The grid searcher runs one Tune experiment ``<name>`` over configurations x seeds; the optuna
  searcher runs one experiment per seed, ``<name>-seed<s>`` (study ``<name>-seed<s>``, sampler seed
  ``searcher.seed + index``), one after the other.
* The trainable is the algorithm's trial class (registry; for CO-PILOT ``CoPilotTrial`` in
  ``copilot_ray.algorithms.copilot.trial``; the Tune callbacks are in ``copilot_ray.tune_runtime``), a
  subclass of ``CoPilot`` built from a FLAT Tune config (the
  trial's dotted params + ``seed`` + ``_spec_path``) with ``build_algorithm_config``; RLlib's own
  ``save_checkpoint`` / ``load_checkpoint`` carry the whole state, so a trial that fails (up to 2 times)
  or is resumed continues from its last checkpoint.
* Terminal: one line per trial result (K, b, alpha schedule, seed, env steps, success), and at the end a
  summary per configuration, where the results are and the ``mlflow ui`` command.
* Ctrl-C / SIGTERM: Tune stops the trials, saves its state and the command prints how to resume (exit
  130). ``--resume`` continues: finished trials are not re-run, unfinished and errored ones continue from
  their last checkpoint, the same MLflow parent and child runs are reused (no duplicates; metric rows
  already logged are not logged again). A file of several parts also resumes from its MLflow store alone
  (copied to a new machine without ``tune/``): parts the store records finished are skipped, the others
  start over (an unfinished attempt's runs are discarded first). ``python -m copilot_ray.carry`` packs
  the store with the interrupted part's Tune folder, so that part continues from its checkpoints instead.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from copilot_ray import tracking
from copilot_ray.cluster_address import address_problem
from copilot_ray.commands import python_module, relative_path
from copilot_ray.console import quiet_console
from copilot_ray.keys import (
    ALGORITHM_TAG,
    BUDGET_PARAM,
    ENV_PARAM,
    ENV_STEPS,
    ENV_TAG,
    EVAL_SUCCESS,
    PATH_SUCCESS,
    RESOLVED_SPEC_ARTIFACT,
    SEARCHER_PARAM,
    SEARCHES,
    SEED_PARAM,
    SPEC_ARTIFACT,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    TUNE_PATH_TAG,
    VARIANT_TAG,
    validation_key,
)
from copilot_ray.mlflow_view import column
from copilot_ray.registry import get_algorithm, metric_known
from copilot_ray.store import missing_sqlite_file, tracking_uri_problem, ui_hint, unwritable, unwritable_store
from copilot_ray.sweep_spec import SpecError, SpecLoader, format_plan, load_spec, load_specs, parse_spec
from copilot_ray.sweep_spec.comparison import overshoot_warnings
from copilot_ray.sweep_spec.estimate import gpu_problem, local_gpus, total_wall_time_line
from copilot_ray.sweep_summary import (
    SweepOutcome,
    TrialRow,
    rows_from_grid,
    summary_keys,
    summary_metrics,
    summary_note,
    summary_table,
)
from copilot_ray.trials.description import config_key, env_params

EXIT_INTERRUPTED = 130


class SweepError(RuntimeError):
    """A sweep that cannot start as asked (results exist without --resume, nothing to resume, ...)."""


# ================================================================================================ paths
def sweep_root(spec) -> Path:
    return Path(spec.tracking.storage) / spec.name


def experiment_names(spec) -> list[tuple[str, int | None]]:
    """(Tune experiment name, seed or None): one for a grid, one per seed for optuna."""
    if spec.searcher.type == "grid":
        return [(spec.name, None)]
    return [(f"{spec.name}-seed{seed}", seed) for seed in spec.seeds]


def _absolute_layout(layout: Any) -> Any:
    """A layout file's absolute path; a built-in layout's name (or an inline layout) as it is."""
    if isinstance(layout, str) and Path(layout).expanduser().is_file():
        return str(Path(layout).expanduser().resolve())
    return layout


def write_resolved_spec(spec, destination: Path, tracking_uri: str | None = None) -> Path:
    """The spec as it runs: absolute storage, the tracking URI and layout files resolved, re-validated."""
    data = spec.document  # this spec's own part of its file, as written
    if spec.best_of is not None and spec.best_of.chosen is not None:
        # What stage 2 runs with, read from stage 1's store once: a resumed part keeps it.
        data["best_of"] = {
            **(data.get("best_of") or {}),
            "chosen": dict(spec.best_of.chosen),
            "chosen_from": spec.best_of.chosen_from,
        }
    data.setdefault("tracking", {})
    data["tracking"] = {**(data["tracking"] or {}), "storage": spec.tracking.storage}
    data["tracking"]["uri"] = tracking_uri or spec.tracking.uri
    env_config = (data.get("env") or {}).get("config") or {}
    if "layout" in env_config:
        env_config["layout"] = _absolute_layout(env_config["layout"])  # trials run in their own cwd
    destination.parent.mkdir(parents=True, exist_ok=True)
    text = (
        f"# {spec.name}: resolved copy of {Path(spec.source).resolve()} (written by copilot_ray.sweep)\n"
        + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
    )
    parse_spec(yaml.load(text, Loader=SpecLoader), str(destination))  # noqa: S506 - still valid?
    destination.write_text(text)
    return destination


# ================================================================================================ running
@dataclass
class SweepRun:
    """A sweep about to run (resolved, not yet started)."""

    spec: Any  # as it runs: read back from saved_spec
    uri: str  # MLflow tracking URI
    resume: bool
    given: Path  # the spec file as given
    root: Path  # <tracking.storage>/<name>
    saved_spec: Path  # root/spec.yaml
    experiments: list[tuple[str, int | None]]  # (Tune experiment name, seed or None)

    @property
    def tune_root(self) -> Path:
        return self.root / "tune"


def run_sweep(
    spec,
    *,
    resume: bool = False,
    address: str | None = None,
    tracking_uri: str | None = None,
    extra_callbacks: Sequence[Any] = (),
) -> SweepOutcome:
    """Runs (or resumes) a validated spec. Uses an already-initialised Ray as is and leaves it running;
    otherwise starts one (``address``: connect to that cluster) and shuts it down at the end.

    ``extra_callbacks`` (Tune callbacks) are used on a fresh run only: on resume Tune restores the
    callbacks it pickled with the experiment.
    """
    started = time.time()
    run = resolve_sweep(spec, resume=resume, tracking_uri=tracking_uri)
    runtime = _import_runtime()
    own_ray = runtime.start_ray(address)
    exp_id, parent_id = open_tracking(run)
    rows, interrupted, tune_paths = run_experiments(run, runtime, exp_id, parent_id, extra_callbacks)
    outcome = report_sweep(
        run, rows, interrupted, tune_paths, parent_id, wall=time.time() - started, exp_id=exp_id
    )
    if own_ray:
        runtime.stop_ray()
    return outcome


def resolve_sweep(spec, *, resume: bool, tracking_uri: str | None) -> SweepRun:
    """Checks that ``resume`` matches what is on disk and settles the spec the sweep runs with: on resume
    the saved ``spec.yaml``, otherwise ``spec`` written there resolved (``write_resolved_spec``)."""
    root = sweep_root(spec)
    experiments = experiment_names(spec)
    _check_resume(root, experiments, resume)
    saved_spec = root / "spec.yaml"
    if resume and saved_spec.is_file():
        running = load_spec(saved_spec)
        for line in resume_notes(running, spec, saved_spec):
            _say(line)
        experiments = experiment_names(running)  # a search's seeds too: the ones it began with
    else:
        if spec.best_of is not None and spec.best_of.chosen is None:
            spec = choose_best_of(spec, tracking_uri)
        write_resolved_spec(spec, saved_spec, tracking_uri)
        running = load_spec(saved_spec)
    uri = tracking_uri or running.tracking.uri
    return SweepRun(running, uri, resume, Path(spec.source), root, saved_spec, experiments)


def _as_compared(spec) -> dict[str, Any]:
    """What a resumed sweep's saved spec and the file given to --resume must agree on: everything but
    what resolving writes into the saved copy (tracking, stage 1's winner, absolute layout paths)."""
    data = spec.model_dump(exclude={"tracking"})
    if data.get("best_of"):
        data["best_of"] = {k: v for k, v in data["best_of"].items() if k not in ("chosen", "chosen_from")}
    env_config = (data.get("env") or {}).get("config") or {}
    if "layout" in env_config:
        env_config["layout"] = _absolute_layout(env_config["layout"])
    return data


def resume_notes(running, given, saved_spec: Path) -> list[str]:
    """Lines for --resume when the file given differs from the spec the sweep began with (which is the
    one that runs). Added seeds get their own line: a started Tune experiment takes no new trials."""
    before, now = _as_compared(running), _as_compared(given)
    changed = [key for key in now if before.get(key) != now.get(key)]
    if not changed:
        return []
    notes = [
        f"note: {given.source} differs from the spec this sweep began with in {', '.join(changed)}; "
        f"resuming with {saved_spec}"
    ]
    added = [seed for seed in given.seeds if seed not in running.seeds]
    if "seeds" in changed and added:
        notes.append(
            f"note: seeds {added} added to {given.source} do not run on --resume, which runs the seeds "
            f"the sweep began with ({list(running.seeds)}): run them as a part of their own, with the "
            f"same config and `seeds: {added}` under another name (as "
            "sweeps/fair_maze_paper_literal_seeds_2_4.yaml does for sweeps/fair_maze.yaml), "
            "and report both with --parent-run all (one store) or --also-from (its own store)"
        )
    return notes


def choose_best_of(spec, tracking_uri: str | None):
    """A copy of stage-2 `spec` with `best_of.chosen`: the winner of its stage-1 sweep (copilot_ray.stages),
    read from that sweep's store now. Raises SweepError when there is none yet."""
    from copilot_ray.stages import StageError, best_configuration

    b = spec.best_of
    uri, experiment = spec.best_of_store(tracking_uri)
    if (missing := missing_sqlite_file(uri)) is not None:  # (MLflow would make an empty store there)
        raise SweepError(f"best_of: there is no store file {missing}: has sweep {b.sweep!r} run there?")
    try:
        winner = best_configuration(uri, experiment, b.sweep, b.metric, b.mode)
    except StageError as err:
        raise SweepError(str(err)) from None
    clashes = sorted(set(winner.values) & set(spec.config))
    if clashes:
        raise SweepError(
            f"best_of: {b.sweep!r} searched {clashes[0]!r}, which {spec.name!r} also fixes in config: keep one"
        )
    chosen = spec.model_copy(deep=True)
    chosen.best_of = b.model_copy(
        update={"chosen": winner.values, "chosen_from": winner.provenance(b.sweep, b.metric)}
    )
    chosen._source, chosen._document = spec.source, spec.document
    _say(f"{spec.name}: configuration = {winner.values} ({chosen.best_of.chosen_from})")
    return chosen


def _check_resume(root: Path, experiments: list[tuple[str, int | None]], resume: bool) -> None:
    tune_root = root / "tune"
    existing = [name for name, _ in experiments if (tune_root / name).exists()]
    if not resume and existing:
        raise SweepError(
            f"{tune_root / existing[0]} already holds this sweep's results: add --resume to continue it, "
            f"or remove {root} (or rename the sweep) to start over"
        )
    if resume and not existing:
        raise SweepError(f"nothing to resume: no Tune experiment under {tune_root}")


def _import_runtime():
    """``copilot_ray.tune_runtime``, which imports Ray: only ever called with a validated spec."""
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    # On Ctrl-C Tune waits for each trial's current iteration to end before stopping it, by default up
    # to 600 s (one demo iteration takes minutes); the state is saved already, so stop them sooner.
    os.environ.setdefault("TUNE_FORCE_TRIAL_CLEANUP_S", "20")
    # Tune's newer console output prints a box of the experiment's settings and a TensorBoard command
    # (not installed here) even at verbose=0; the older one prints nothing there. ProgressPrinter prints
    # the sweep's own lines.
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    from copilot_ray import tune_runtime

    return tune_runtime


def open_tracking(run: SweepRun) -> tuple[str, str]:
    """The sweep's MLflow parent run (the same one on resume) with the spec files: (experiment id, run id)."""
    spec = run.spec
    exp_id, parent_id, reused = tracking.open_sweep_run(
        run.uri,
        spec.experiment,
        spec.name,
        resume=run.resume,
        tags={
            TUNE_PATH_TAG: str(run.tune_root),
            ALGORITHM_TAG: spec.algorithm,
            ENV_TAG: ",".join(spec.env.ids),
        },
        params=_sweep_params(spec),
        artifact_location=tracking.local_artifact_location(run.uri, run.root / "mlartifacts"),
        description=spec.description,
    )
    tracking.show_trials(run.uri, exp_id, *trials_view_of(spec))
    if not reused:
        files = {RESOLVED_SPEC_ARTIFACT: run.saved_spec}
        if not run.resume and run.given.is_file():
            files[SPEC_ARTIFACT] = run.given
        tracking.log_sweep_files(run.uri, parent_id, files)
    _say(
        f"sweep {spec.name!r}: {len(spec.trial_plan())} trial(s); Tune results in {run.tune_root}; "
        f"MLflow {run.uri} (parent run {parent_id}{', resumed' if reused else ''})"
    )
    return exp_id, parent_id


def trials_view_of(spec) -> tuple[list[tuple[str, str]] | None, list[str], list[str]]:
    """What the MLflow link shows of this part (copilot_ray.mlflow_view): its configurations (a grid's,
    known in advance; None for a search), the columns (what it varies, the seed, the figures the
    terminal summary shows (a search: none of the test tasks'), env steps) and what the chart draws."""
    searched = spec.searcher.type in SEARCHES
    configurations = (
        None if searched else sorted({(spec.algorithm, config_key(flat)) for flat in spec.trial_plan()})
    )
    varied = [*spec.searched_keys, *([ENV_PARAM] if len(spec.env.ids) > 1 else []), SEED_PARAM]
    columns = [
        *([column("tags", VARIANT_TAG)] if spec.variants else []),
        *(column("params", p) for p in varied),
    ]
    # the summary's headline figures that the algorithm logs (its METRICS: a planner logs no validation
    # success, HER no paths), the planned / direct split left to the summary (a table that fits)
    logged = get_algorithm(spec.algorithm).metrics
    shown = [
        k
        for k in summary_keys(searched)
        if k not in (validation_key(SUCCESS_PLANNED), validation_key(SUCCESS_DIRECT))
        and metric_known(k, logged)
    ]
    columns += [column("metrics", m) for m in (*shown, ENV_STEPS)]
    charts = [validation_key(EVAL_SUCCESS), *([] if searched else [PATH_SUCCESS])]
    return configurations, columns, [m for m in charts if metric_known(m, logged)]


def _sweep_params(spec) -> dict[str, Any]:
    """The sweep's shape, as the parent run's params."""
    return {
        "algorithm": spec.algorithm,
        **env_params(spec, ",".join(spec.env.ids)),
        SEARCHER_PARAM: spec.searcher.type,
        "seeds": list(spec.seeds),
        "trials": len(spec.trial_plan()),
        BUDGET_PARAM: spec.stop.env_steps,
        "stop.iterations": spec.stop.iterations,
        "searched": ",".join(spec.searched_keys) or "-",
        **(
            {"best_of.chosen": spec.best_of.chosen, "best_of.from": spec.best_of.chosen_from}
            if spec.best_of is not None
            else {}
        ),
    }


def run_experiments(
    run: SweepRun, runtime, exp_id: str, parent_id: str, extra_callbacks: Sequence[Any]
) -> tuple[list[TrialRow], bool, list[str]]:
    """Fits the sweep's Tune experiments one after the other: (rows, interrupted, Tune paths).

    Stops at the first experiment that did not run all its trials (Ctrl-C / SIGTERM)."""
    previous_term = None
    if threading.current_thread() is threading.main_thread():
        # Tune handles SIGINT (save state, stop trials); route SIGTERM the same way.
        previous_term = signal.signal(signal.SIGTERM, lambda *_: os.kill(os.getpid(), signal.SIGINT))
    rows: list[TrialRow] = []
    tune_paths: list[str] = []
    try:
        for index, (exp_name, seed) in enumerate(run.experiments):
            tune_paths.append(str(run.tune_root / exp_name))
            tuner = _tuner(run, runtime, index, exp_name, seed, exp_id, parent_id, extra_callbacks)
            new_rows = rows_from_grid(tuner.fit())
            rows.extend(new_rows)
            expected = len(run.spec.trial_plan()) if seed is None else run.spec.searcher.num_samples
            # Unfinished trials, or trials never created (Tune creates them lazily): interrupted.
            if len(new_rows) < expected or any(r.status == "unfinished" for r in new_rows):
                return rows, True, tune_paths
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)
    return rows, False, tune_paths


def _tuner(run: SweepRun, runtime, index, exp_name, seed, exp_id, parent_id, extra_callbacks):
    """The experiment restored from its Tune state (resume), or built fresh with the sweep's callbacks."""
    if run.resume:
        tuner = runtime.restore_tuner(run.spec, run.tune_root / exp_name)
        if tuner is not None:
            return tuner
    callbacks = [
        runtime.ProgressPrinter(),
        runtime.MlflowSweepCallback(
            run.uri, exp_id, run.spec.name, parent_id, run.spec.tracking.rllib_timers
        ),
        *extra_callbacks,
    ]
    root = sweep_root(run.spec)
    return runtime.build_tuner(run.spec, run.saved_spec, root, exp_name, seed, index, callbacks)


def report_sweep(
    run: SweepRun,
    rows: list[TrialRow],
    interrupted: bool,
    tune_paths: list[str],
    parent_id: str,
    wall: float,
    exp_id: str | None = None,
) -> SweepOutcome:
    """Ends the parent run with the summary table and prints it, where the results are and what next."""
    spec, uri = run.spec, run.uri
    searched = spec.searcher.type in SEARCHES
    summary = summary_table(rows, searched)
    errored = any(r.status == "error" for r in rows)
    status = "interrupted" if interrupted else ("errored" if errored else "finished")
    note = summary_note(rows, searched)
    header = (
        f"# sweep {spec.name}: {status}\n\n{len(rows)} trial(s), wall {wall:.0f}s (this session). {note}\n\n"
    )
    mlflow_status = {"finished": "FINISHED", "errored": "FAILED", "interrupted": "KILLED"}[status]
    tracking.end_sweep_run(
        uri,
        parent_id,
        mlflow_status,
        header + summary + "\n",
        summary_metrics(rows, searched),
        step=sum(int(r.env_steps) for r in rows),
    )
    _say("")
    _say(summary)
    _say(note)
    _say("")
    _say(f"Tune results: {', '.join(tune_paths)}")
    _say(f"MLflow store: {uri} (experiment {spec.experiment!r}, parent run {parent_id})")
    command, *then = ui_hint(uri, exp_id, trials_view=True)
    _say(f"MLflow UI: {command}")
    for line in then:
        _say(f"  {line}")
    _say(f"Report: {report_command(spec, uri)}")
    if interrupted:
        _say(f"interrupted: state saved. Resume with: {resume_command(run.given)}")
    elif errored:
        stopped = [r for r in rows if r.status == "error" and r.stacked]
        if len(stopped) < sum(r.status == "error" for r in rows):
            _say(
                f"some trials failed; retry them from their last checkpoint with: {resume_command(run.given)}"
            )
        if stopped:
            _say(
                "seeds that stopped alone in a stacked trial (their MLflow runs are FAILED with the error): "
                + ", ".join(f"seed {r.seed} of {r.config_key}" for r in stopped)
                + "; a stack does not retry a seed: run them again as a part of their own (`seeds: [..]`)"
            )
    code = EXIT_INTERRUPTED if interrupted else (1 if errored else 0)
    return SweepOutcome(status, code, rows, summary, uri, parent_id, tune_paths, wall)


def report_command(spec, uri: str) -> str:
    """The exact command that draws this sweep's report: every sweep of its experiment (the parts of a
    comparison file, stage-2 of a two-stage one) from the store it wrote to."""
    return python_module("analysis.report", spec.experiment, "--parent-run", "all", "--tracking-uri", uri)


def resume_command(given: Path) -> str:
    """The command that continues this sweep file where it stopped: the file as the user gave it (a
    relative path stays relative), not the resolved copy the sweep keeps beside its results."""
    return python_module("copilot_ray.sweep", given, "--resume")


def _say(line: str) -> None:
    print(line, flush=True)


# ================================================================================================ CLI
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog=python_module("copilot_ray.sweep"), description=__doc__.split("\n\n")[0])
    p.add_argument(
        "spec", help="sweep spec YAML (format: copilot_ray/sweep_spec/__init__.py; examples: sweeps/)"
    )
    p.add_argument("--check", action="store_true", help="validate and print the plan; start nothing")
    p.add_argument("--resume", action="store_true", help="continue an interrupted or failed sweep")
    p.add_argument(
        "--address",
        default=None,
        help="Ray cluster address, e.g. auto (default: a local Ray of its own, whatever RAY_ADDRESS says)",
    )
    p.add_argument("--tracking-uri", default=None, help="MLflow tracking URI (default: the spec's)")
    p.add_argument(
        "--verbose",
        action="store_true",
        help="show Ray's, RLlib's, Tune's and MLflow's notices on the console (default: only in "
        "<storage>/<name>/console.log)",
    )
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    problems = []
    if args.tracking_uri is not None and (why := tracking_uri_problem(args.tracking_uri)) is not None:
        problems.append(f"--tracking-uri {args.tracking_uri!r} is invalid: {why}")
    if args.address and (why := address_problem(args.address)) is not None:
        problems.append(f"--address {args.address!r} is invalid: {why}")
    try:
        specs = load_specs(args.spec)
    except SpecError as err:
        problems += err.problems
    if not problems:
        problems += storage_problems(specs, args.tracking_uri)
    no_gpus = []  # on a local Ray, trials asking for GPUs the machine lacks would wait for ever
    if not problems and not args.address and any(spec.resources.gpus_per_trial > 0 for spec in specs):
        gpus = local_gpus()
        no_gpus = [why for spec in specs if (why := gpu_problem(spec, gpus)) is not None]
    if problems or (no_gpus and not args.check):
        for line in problems or no_gpus:
            print(line, file=sys.stderr)
        return 2
    if args.check:
        cpus, where = _available_cpus(args.address)
        print("\n\n".join(format_plan(spec, args.tracking_uri, cpus, where) for spec in specs))
        if len(specs) > 1:
            print(f"\n{total_wall_time_line(specs)}")
            for line in overshoot_warnings(specs):
                print(line)
        for why in no_gpus:
            print(f"warning: {why}")
        return 0
    if (refusal := start_problem(specs, args.spec, args.resume, args.tracking_uri)) is not None:
        print(f"error: {refusal}", file=sys.stderr)
        return 2
    console = quiet_console(args.verbose)  # (it keeps what it leaves out in memory until log_to)
    try:
        stage_two = specs[0].best_of is not None and specs[0].best_of.chosen is None
        if len(specs) == 1 and not args.resume and stage_two:
            # A stage 2 part run alone reads stage 1's winner now, so that none yet is refused before
            # Ray and before any file (in a file with its stage 1, once that part has run).
            try:
                specs = [choose_best_of(specs[0], args.tracking_uri)]
            except SweepError as err:
                print(f"error: {err}", file=sys.stderr)
                return 2
        if console is not None:
            console.log_to(sweep_root(specs[0]) / "console.log")
            _say(
                f"sweep {args.spec}: starting Ray (Ray's, RLlib's, Tune's and MLflow's notices go to "
                f"{relative_path(console.path)}; --verbose shows them)"
            )
        if len(specs) == 1:
            return _run_one(specs[0], args, resume=args.resume)
        return _run_parts(specs, args)
    finally:
        if console is not None:
            console.close()


def started_parts(specs: Sequence[Any]) -> list[str]:
    """The names of the parts whose Tune experiments exist (they ran, or began to)."""
    return [
        spec.name
        for spec in specs
        if any((sweep_root(spec) / "tune" / name).exists() for name, _ in experiment_names(spec))
    ]


def start_problem(specs: Sequence[Any], file: str, resume: bool, tracking_uri: str | None) -> str | None:
    """Why the sweep file cannot start as asked (results there without --resume, nothing to resume), or
    None: said before Ray starts and before anything is written (its console log included)."""
    if len(specs) == 1:
        spec = specs[0]
        try:
            _check_resume(sweep_root(spec), experiment_names(spec), resume)
        except SweepError as err:
            return str(err)
        return None
    started = started_parts(specs)
    if started and not resume:
        return (
            f"part {started[0]!r} of {file} has results already: add --resume to continue the file's "
            "sweeps, or remove it to start over"
        )
    # A file's parts also resume from their store alone (carried here without Tune folders): refused
    # only when there is neither.
    stores = [missing_sqlite_file(tracking_uri or spec.tracking.uri) for spec in specs]
    if resume and not started and all(stores):
        return (
            f"nothing to resume: no part of {file} has run here (no Tune experiment under "
            f"{sweep_root(specs[0]) / 'tune'}, no store {stores[0]})"
        )
    return None


def storage_problems(specs: Sequence[Any], tracking_uri: str | None = None) -> list[str]:
    """Where a spec's results would go but cannot be written (a file in the way, no permission), one line
    each naming the key and its value: said before Ray starts, not as a traceback from the sweep."""
    lines = []
    for spec in specs:
        where = f"{spec.source}" + (f" (part {spec.name!r})" if len(specs) > 1 else "")
        if (why := unwritable(sweep_root(spec))) is not None:
            lines.append(f"{where}: tracking.storage: {spec.tracking.storage!r} is invalid: {why}")
        given_uri = ((spec.document or {}).get("tracking") or {}).get("uri")  # else under the storage
        if tracking_uri is None and given_uri and (why := unwritable_store(spec.tracking.uri)) is not None:
            lines.append(f"{where}: tracking.uri: {spec.tracking.uri!r} is invalid: {why}")
    if tracking_uri is not None and (why := unwritable_store(tracking_uri)) is not None:
        lines.append(f"--tracking-uri {tracking_uri!r} is invalid: {why}")
    return list(dict.fromkeys(lines))


def _available_cpus(address: str | None) -> tuple[int | None, str]:
    """The CPUs a plan can use: this machine's, or (--address) the cluster's, read without starting
    anything (a cluster that cannot be reached is said, not fatal: --check is a plan)."""
    if not address:
        return os.cpu_count(), "this machine"
    runtime = _import_runtime()
    try:
        return runtime.cluster_cpus(address), f"the cluster at {address}"
    except Exception as err:  # noqa: BLE001 - any failure to reach it: no figure, the reason said
        _say(f"note: could not read the resources of the cluster at {address} ({type(err).__name__}: {err})")
        return None, f"the cluster at {address}"


def _run_one(spec, args, *, resume: bool) -> int:
    try:
        outcome = run_sweep(spec, resume=resume, address=args.address, tracking_uri=args.tracking_uri)
    except SweepError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return outcome.exit_code


def _run_parts(specs: Sequence[Any], args) -> int:
    """A file of several specs: each runs as its own sweep, in order, on one Ray. Without --resume no
    part may have results yet (checked before anything starts); with it, the parts that started resume and
    the others start. An interrupted or failed part ends the run (--resume continues from it)."""
    started = started_parts(specs)  # (results without --resume were refused before: start_problem)
    runtime = _import_runtime()
    own_ray = runtime.start_ray(args.address)
    try:
        for i, spec in enumerate(specs, start=1):
            _say(f"=== part {i} of {len(specs)}: {spec.name} ({spec.algorithm})")
            if args.resume and spec.name not in started and _done_in_store(spec, args.tracking_uri):
                continue
            code = _run_one(spec, args, resume=spec.name in started)
            if code != 0:
                return code
        return 0
    finally:
        if own_ray:
            runtime.stop_ray()


def _done_in_store(spec, tracking_uri: str | None) -> bool:
    """For a part with no Tune folder under --resume (its store was carried here alone): True when the
    store records it finished (skip it). Runs of an unfinished earlier attempt are discarded first, since
    the part starts over and would otherwise be counted twice (reports, best_of)."""
    uri = tracking_uri or spec.tracking.uri
    finished, runs = tracking.sweep_runs_in_store(uri, spec.experiment, spec.name)
    if finished:
        _say(f"{spec.name}: finished in {uri} (parent run {finished}); skipped")
        return True
    if runs:
        tracking.discard_runs(uri, runs)
        _say(f"{spec.name}: discarded {len(runs)} run(s) of an unfinished attempt whose Tune state is gone")
    studies = sweep_root(spec) / "optuna.db"
    if studies.is_file():  # its Optuna studies would otherwise feed the old trials to the new search
        aside = studies.with_name(f"optuna.discarded-{int(time.time())}.db")
        studies.rename(aside)
        _say(f"{spec.name}: moved the unfinished attempt's Optuna studies aside to {aside}")
    return False


if __name__ == "__main__":
    raise SystemExit(main())
