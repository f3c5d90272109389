"""Run a sweep spec on Ray Tune, tracked in MLflow.

    python -m copilot_ray.sweep SPEC.yaml [--check] [--resume] [--address ADDR] [--tracking-uri URI]

* The spec is validated first (``copilot_ray.spec.load_spec``): a bad spec prints one line per problem
  (file, key path, value, why) on stderr and exits 2 before Ray is imported. ``--check`` prints the plan
  (configurations x seeds, trials, budget) and exits 0, also without Ray.
* Running: a local Ray with ``os.cpu_count()`` CPUs, or the cluster at ``--address``. Everything lands in
  ``<tracking.storage>/<name>/``: ``spec.yaml`` (the spec as resolved: absolute paths; trials and
  ``--resume`` read this copy), ``tune/<experiment>/`` (Tune's state, trial folders, checkpoints),
  ``mlflow.db`` + ``mlartifacts/`` (the default MLflow store) and, for optuna, ``optuna.db`` (the
  studies). The grid searcher runs one Tune experiment ``<name>`` over configurations x seeds; the optuna
  searcher runs one experiment per seed, ``<name>-seed<s>`` (study ``<name>-seed<s>``, sampler seed
  ``searcher.seed + index``), one after the other.
* The trainable is ``CoPilotTrial``, a subclass of ``CoPilot`` built from a FLAT Tune config (the
  trial's dotted params + ``seed`` + ``_spec_path``) with ``build_algorithm_config``; RLlib's own
  ``save_checkpoint`` / ``load_checkpoint`` carry the whole state, so a trial that fails (up to 2 times)
  or is resumed continues from its last checkpoint.
* Terminal: one line per trial result (K, b, alpha schedule, seed, env steps, success), and at the end a
  summary per configuration, where the results are and the ``mlflow ui`` command.
* Ctrl-C / SIGTERM: Tune stops the trials, saves its state and the command prints how to resume (exit
  130). ``--resume`` continues: finished trials are not re-run, unfinished and errored ones continue from
  their last checkpoint, the same MLflow parent and child runs are reused (no duplicates; metric rows
  already logged are not logged again).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from copilot_ray.tracking import (
    ENV_STEPS_KEY,
    SPEC_PATH_KEY,
    config_key,
    describe_trial,
    result_value,
    trial_flat,
)

SUCCESS_KEYS = ("copilot/eval/success_planned", "copilot/eval/success_direct")
CHECKPOINT_FREQUENCY = 1  # iterations between checkpoints (and the synced copilot_trees/)
MAX_FAILURES = 2
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


def write_resolved_spec(spec, destination: Path, tracking_uri: str | None = None) -> Path:
    """The spec as it runs: absolute storage, the tracking URI and layout files resolved, re-validated."""
    import yaml

    from copilot_ray.spec import _SpecLoader, parse_spec

    data = yaml.load(Path(spec.source).read_text(), Loader=_SpecLoader)  # noqa: S506 - SafeLoader subclass
    data.setdefault("tracking", {})
    data["tracking"] = {**(data["tracking"] or {}), "storage": spec.tracking.storage}
    data["tracking"]["uri"] = tracking_uri or spec.tracking.uri
    env_config = (data.get("env") or {}).get("config") or {}
    layout = env_config.get("layout")
    if isinstance(layout, str) and Path(layout).expanduser().is_file():
        env_config["layout"] = str(Path(layout).expanduser().resolve())  # trials run in their own cwd
    destination.parent.mkdir(parents=True, exist_ok=True)
    text = (
        f"# {spec.name}: resolved copy of {Path(spec.source).resolve()} (written by copilot_ray.sweep)\n"
        + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
    )
    parse_spec(yaml.load(text, Loader=_SpecLoader), str(destination))  # noqa: S506 - still valid?
    destination.write_text(text)
    return destination


# ================================================================================================ Tune parts
def _make_trial_class():
    from copilot_ray.algorithms.copilot import CoPilot

    class CoPilotTrial(CoPilot):
        """CoPilot built from a flat Tune config: ``{dotted params..., "seed": s, "_spec_path": p}``.

        ``__init__`` and ``default_resource_request`` turn the flat dict into the RLlib config with
        ``build_algorithm_config(flat, spec)`` (spec loaded from ``_spec_path``), so Tune's placement
        group fits the env runners and RLlib's checkpointing is untouched.

        Every result carries ``copilot/eval/success_*`` (Tune's strict metric check and Optuna need the
        searched metric in every result): iterations without an evaluation repeat the last evaluated
        value (NaN before the first one) and set ``copilot/eval/fresh`` to 0 (1 when evaluated now).
        """

        def __init__(self, config=None, **kwargs):
            if isinstance(config, dict) and SPEC_PATH_KEY in config:
                config = _algorithm_config(config)
            self._last_eval: dict[str, float] = {}
            super().__init__(config=config, **kwargs)

        @classmethod
        def default_resource_request(cls, config):
            if isinstance(config, dict) and SPEC_PATH_KEY in config:
                config = _algorithm_config(config)
            return super().default_resource_request(config)

        def step(self):
            result = super().step()
            copilot = result.setdefault("copilot", {})
            ev = copilot.setdefault("eval", {})
            # RLlib reports a window-1 stat logged in an earlier iteration as NaN: not an evaluation.
            fresh = all(_is_number(ev.get(k.rsplit("/", 1)[1])) for k in SUCCESS_KEYS)
            for key in SUCCESS_KEYS:
                name = key.rsplit("/", 1)[1]
                if fresh:
                    self._last_eval[name] = float(ev[name])
                else:
                    ev[name] = self._last_eval.get(name, float("nan"))
            ev["fresh"] = 1.0 if fresh else 0.0
            return result

        def get_state(self, *args, **kwargs):
            state = super().get_state(*args, **kwargs)
            state["copilot_trial_last_eval"] = dict(getattr(self, "_last_eval", {}))
            return state

        def set_state(self, state):
            super().set_state(state)
            self._last_eval = dict(state.get("copilot_trial_last_eval", {}))

    CoPilotTrial.__module__ = __name__
    CoPilotTrial.__qualname__ = "CoPilotTrial"
    return CoPilotTrial


def _algorithm_config(config: Mapping[str, Any]):
    from copilot_ray.spec import build_algorithm_config
    from copilot_ray.tracking import _load_spec_cached

    spec = _load_spec_cached(str(config[SPEC_PATH_KEY]))
    return build_algorithm_config(trial_flat(config), spec)


def _make_progress_printer():
    from ray.tune import Callback

    class ProgressPrinter(Callback):
        """One line per trial event; replaces Tune's table (which dumps the whole RLlib config)."""

        def __init__(self):
            self._info: dict[str, dict[str, Any]] = {}

        def __getstate__(self):
            return {}

        def __setstate__(self, state):
            self._info = {}

        def _head(self, trial) -> str:
            info = self._info.get(trial.trial_id)
            if info is None:
                try:
                    d = describe_trial(trial.config)
                    info = {k: d[k] for k in ("config_key", "K", "b", "alpha_schedule", "seed")}
                except Exception as err:  # noqa: BLE001 - a progress line must not fail the sweep
                    info = {
                        "config_key": f"? ({err})",
                        "K": "?",
                        "b": "?",
                        "alpha_schedule": "?",
                        "seed": "?",
                    }
                self._info[trial.trial_id] = info
            i = info
            return (
                f"[{trial.trial_id}] {i['config_key']:<18} K={i['K']} b={i['b']} "
                f"alpha={i['alpha_schedule']} seed={i['seed']}"
            )

        def on_trial_start(self, iteration, trials, trial, **info):
            _say(f"{self._head(trial)}  started")

        def on_trial_result(self, iteration, trials, trial, result, **info):
            ev = result.get("copilot", {}).get("eval", {})
            steps = result_value(result, ENV_STEPS_KEY, 0)
            mark = "" if ev.get("fresh", 1.0) else " (last eval)"
            _say(
                f"{self._head(trial)}  iter {result.get('training_iteration', 0):4d}  "
                f"env_steps {int(steps):8d}  success planned {_fmt(ev.get('success_planned'))} "
                f"direct {_fmt(ev.get('success_direct'))}{mark}  {result.get('time_total_s', 0.0):7.1f}s"
            )

        def on_trial_complete(self, iteration, trials, trial, **info):
            _say(f"{self._head(trial)}  done")

        def on_trial_recover(self, iteration, trials, trial, **info):
            _say(f"{self._head(trial)}  failed, retrying from its last checkpoint ({trial.error_file})")

        def on_trial_error(self, iteration, trials, trial, **info):
            _say(f"{self._head(trial)}  ERROR, see {trial.error_file}")

    ProgressPrinter.__module__ = __name__
    ProgressPrinter.__qualname__ = "ProgressPrinter"
    return ProgressPrinter


class _OptunaSpace:
    """``OptunaSearch(space=...)`` define-by-run function; a picklable class (Tune pickles the searcher)."""

    def __init__(self, spec_path: str):
        self.spec_path = spec_path
        self._fn = None

    def __getstate__(self):
        return {"spec_path": self.spec_path}

    def __setstate__(self, state):
        self.spec_path, self._fn = state["spec_path"], None

    def __call__(self, trial):
        if self._fn is None:
            from copilot_ray.spec import optuna_define_by_run
            from copilot_ray.tracking import _load_spec_cached

            self._fn = optuna_define_by_run(_load_spec_cached(self.spec_path))
        return self._fn(trial)


_LAZY = {"CoPilotTrial": _make_trial_class, "ProgressPrinter": _make_progress_printer}


def __getattr__(name: str):  # PEP 562: Ray-based classes exist only once asked for (no Ray for --check)
    if name in _LAZY:
        return _lazy(name)
    raise AttributeError(name)


def _lazy(name: str):
    """The one class object for ``name`` (built once: pickling by reference needs a stable identity)."""
    cls = globals().get(name)
    if cls is None:
        cls = globals()[name] = _LAZY[name]()
    return cls


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and not math.isnan(v)


def _say(line: str) -> None:
    print(line, flush=True)


def _fmt(v: Any) -> str:
    return f"{v:.2f}" if isinstance(v, int | float) and not math.isnan(v) else "  - "


def _searcher(spec, spec_path: Path, index: int, seed: int):
    import optuna
    from ray.tune.search.optuna import OptunaSearch

    s = spec.searcher
    sampler_seed = (s.seed or 0) + index
    sampler = {
        "tpe": lambda: optuna.samplers.TPESampler(seed=sampler_seed),
        "random": lambda: optuna.samplers.RandomSampler(seed=sampler_seed),
        "cmaes": lambda: optuna.samplers.CmaEsSampler(seed=sampler_seed),
    }[s.sampler or "tpe"]()
    storage = optuna.storages.RDBStorage(f"sqlite:///{sweep_root(spec) / 'optuna.db'}")
    return OptunaSearch(
        space=_OptunaSpace(str(spec_path)),
        metric=s.metric,
        mode=s.mode,
        sampler=sampler,
        study_name=f"{spec.name}-seed{seed}",
        storage=storage,
    )


def _build_tuner(spec, spec_path: Path, exp_name: str, seed: int | None, index: int, callbacks: list):
    from ray import tune

    from copilot_ray.spec import to_tune_scheduler, to_tune_search_space, tune_stop

    trainable = _lazy("CoPilotTrial")
    if spec.searcher.type == "grid":
        param_space = {**to_tune_search_space(spec), SPEC_PATH_KEY: str(spec_path)}
        search_alg, num_samples = None, 1
    else:
        param_space = {"seed": seed, SPEC_PATH_KEY: str(spec_path)}
        search_alg, num_samples = _searcher(spec, spec_path, index, seed), spec.searcher.num_samples
    return tune.Tuner(
        trainable,
        param_space=param_space,
        tune_config=tune.TuneConfig(
            search_alg=search_alg,
            scheduler=to_tune_scheduler(spec),
            num_samples=num_samples,
            max_concurrent_trials=spec.resources.max_concurrent_trials,
            reuse_actors=False,
        ),
        run_config=tune.RunConfig(
            name=exp_name,
            storage_path=str(sweep_root(spec) / "tune"),
            stop=tune_stop(spec),
            checkpoint_config=tune.CheckpointConfig(
                checkpoint_frequency=CHECKPOINT_FREQUENCY, checkpoint_at_end=True, num_to_keep=2
            ),
            failure_config=tune.FailureConfig(max_failures=MAX_FAILURES),
            # copilot_trees/ is written to the trial's working dir; sync it into the trial folder.
            sync_config=tune.SyncConfig(sync_artifacts=True),
            callbacks=callbacks,
            verbose=0,
        ),
    )


# ================================================================================================ summary
@dataclass
class TrialRow:
    trial_id: str
    config_key: str
    seed: Any
    status: str  # finished | error | unfinished
    success_planned: float
    success_direct: float
    env_steps: int
    wall_s: float


@dataclass
class SweepOutcome:
    status: str  # finished | errored | interrupted
    exit_code: int
    rows: list[TrialRow] = field(default_factory=list)
    summary: str = ""
    tracking_uri: str = ""
    parent_run_id: str = ""
    tune_paths: list[str] = field(default_factory=list)
    wall_s: float = 0.0


def _last_valid(df, column: str) -> float:
    if df is None or column not in df.columns:
        return float("nan")
    values = df[column].dropna()
    return float(values.iloc[-1]) if len(values) else float("nan")


def rows_from_grid(grid) -> list[TrialRow]:
    """One row per Tune trial of a ResultGrid (Result.config is RLlib's full config: use the trials)."""
    analysis = grid._experiment_analysis  # noqa: SLF001 - the trials with their flat Tune configs
    rows = []
    for trial in sorted(analysis.trials, key=lambda t: t.trial_id):
        flat = trial_flat(trial.config or {})
        m = trial.last_result or {}
        df = analysis.trial_dataframes.get(trial.trial_id)
        if df is not None and "copilot/eval/fresh" in df.columns:
            df = df[df["copilot/eval/fresh"] == 1.0]  # the evaluations themselves
        # After Ctrl-C, Tune's cleanup marks stopped trials TERMINATED too: finished means a final result.
        if trial.status == "ERROR":
            status = "error"
        else:
            status = "finished" if trial.status == "TERMINATED" and m.get("done") else "unfinished"
        rows.append(
            TrialRow(
                trial_id=trial.trial_id,
                config_key=config_key(flat),
                seed=flat.get("seed"),
                status=status,
                success_planned=_last_valid(df, SUCCESS_KEYS[0]),
                success_direct=_last_valid(df, SUCCESS_KEYS[1]),
                env_steps=int(result_value(m, ENV_STEPS_KEY, 0) or 0),
                wall_s=float(m.get("time_total_s", 0.0) or 0.0),
            )
        )
    return rows


def _mean_std(values: Sequence[float]) -> str:
    vals = [v for v in values if not math.isnan(v)]
    if not vals:
        return "-"
    mean = sum(vals) / len(vals)
    if len(vals) == 1:
        return f"{mean:.2f}"
    std = math.sqrt(sum((v - mean) ** 2 for v in vals) / (len(vals) - 1))
    return f"{mean:.2f} ± {std:.2f}"


def summary_table(rows: Sequence[TrialRow]) -> str:
    """A markdown table per configuration: seeds, mean ± sample std over seeds of the final success."""
    groups: dict[str, list[TrialRow]] = {}
    for row in rows:
        groups.setdefault(row.config_key, []).append(row)
    header = [
        "configuration",
        "seeds",
        "success_planned",
        "success_direct",
        "env steps",
        "wall s/trial",
        "status",
    ]
    lines = [header]
    for key, group in groups.items():
        statuses = sorted({r.status for r in group})
        lines.append(
            [
                key,
                ",".join(str(r.seed) for r in group),
                _mean_std([r.success_planned for r in group]),
                _mean_std([r.success_direct for r in group]),
                f"{sum(r.env_steps for r in group) / len(group):,.0f}",
                f"{sum(r.wall_s for r in group) / len(group):.0f}",
                "/".join(statuses),
            ]
        )
    widths = [max(len(str(line[c])) for line in lines) for c in range(len(header))]

    def fmt(cells):
        return "| " + " | ".join(str(c).ljust(w) for c, w in zip(cells, widths, strict=True)) + " |"

    out = [fmt(lines[0]), "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    out += [fmt(line) for line in lines[1:]]
    return "\n".join(out)


# ================================================================================================ running
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
    root = sweep_root(spec)
    tune_root = root / "tune"
    experiments = experiment_names(spec)
    existing = [name for name, _ in experiments if (tune_root / name).exists()]
    saved_spec = root / "spec.yaml"
    original = Path(spec.source)
    if not resume and existing:
        raise SweepError(
            f"{tune_root / existing[0]} already holds this sweep's results: add --resume to continue it, "
            f"or remove {root} (or rename the sweep) to start over"
        )
    if resume and not existing:
        raise SweepError(f"nothing to resume: no Tune experiment under {tune_root}")
    if resume and saved_spec.is_file():
        from copilot_ray.spec import load_spec

        saved = load_spec(saved_spec)
        given = spec.model_dump(exclude={"tracking"})
        if saved.model_dump(exclude={"tracking"}) != given:
            _say(f"note: {spec.source} differs from the spec this sweep ran with; resuming with {saved_spec}")
        spec = saved
        tracking_uri = tracking_uri or spec.tracking.uri
    else:
        write_resolved_spec(spec, saved_spec, tracking_uri)
        from copilot_ray.spec import load_spec

        spec = load_spec(saved_spec)
        tracking_uri = tracking_uri or spec.tracking.uri
    uri = tracking_uri

    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    # On Ctrl-C Tune waits for each trial's current iteration to end before stopping it, by default up
    # to 600 s (one demo iteration takes minutes); the state is saved already, so stop them sooner.
    os.environ.setdefault("TUNE_FORCE_TRIAL_CLEANUP_S", "20")
    import ray
    from ray import tune

    from copilot_ray import tracking

    own_ray = not ray.is_initialized()
    if own_ray:
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False)

    exp_id, parent_id, reused = tracking.open_sweep_run(
        uri,
        spec.experiment,
        spec.name,
        resume=resume,
        tags={tracking.TUNE_PATH_TAG: str(tune_root), "algorithm": spec.algorithm, "env": spec.env.id},
        params={
            "algorithm": spec.algorithm,
            "env.id": spec.env.id,
            **{f"env.config.{k}": v for k, v in spec.env.config.items()},
            "searcher": spec.searcher.type,
            "seeds": list(spec.seeds),
            "trials": len(spec.trial_plan()),
            "stop.env_steps": spec.stop.env_steps,
            "stop.iterations": spec.stop.iterations,
            "searched": ",".join(spec.searched_keys) or "-",
        },
        artifact_location=tracking.local_artifact_location(uri, root / "mlartifacts"),
    )
    if not reused:
        files = {"spec.resolved.yaml": saved_spec}
        if not resume and original.is_file():
            files["spec.yaml"] = original
        tracking.log_sweep_files(uri, parent_id, files)
    _say(
        f"sweep {spec.name!r}: {len(spec.trial_plan())} trial(s); Tune results in {tune_root}; "
        f"MLflow {uri} (parent run {parent_id}{', resumed' if reused else ''})"
    )

    previous_term = None
    if threading.current_thread() is threading.main_thread():
        # Tune handles SIGINT (save state, stop trials); route SIGTERM the same way.
        previous_term = signal.signal(signal.SIGTERM, lambda *_: os.kill(os.getpid(), signal.SIGINT))

    rows: list[TrialRow] = []
    interrupted = False
    tune_paths = []
    try:
        for index, (exp_name, seed) in enumerate(experiments):
            path = tune_root / exp_name
            tune_paths.append(str(path))
            if resume and path.exists() and tune.Tuner.can_restore(str(path)):
                tuner = tune.Tuner.restore(str(path), trainable=_lazy("CoPilotTrial"), resume_errored=True)
            else:
                callbacks = [
                    _lazy("ProgressPrinter")(),
                    tracking.mlflow_callback_class()(uri, exp_id, spec.name, parent_id),
                    *extra_callbacks,
                ]
                tuner = _build_tuner(spec, saved_spec, exp_name, seed, index, callbacks)
            grid = tuner.fit()
            new_rows = rows_from_grid(grid)
            rows.extend(new_rows)
            expected = len(spec.trial_plan()) if seed is None else spec.searcher.num_samples
            # Unfinished trials, or trials never created (Tune creates them lazily): interrupted.
            if len(new_rows) < expected or any(r.status == "unfinished" for r in new_rows):
                interrupted = True
                break
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)

    summary = summary_table(rows)
    errored = any(r.status == "error" for r in rows)
    status = "interrupted" if interrupted else ("errored" if errored else "finished")
    wall = time.time() - started
    header = (
        f"# sweep {spec.name}: {status}\n\n{len(rows)} trial(s), wall {wall:.0f}s (this session). "
        "Success = last evaluation of each trial; mean ± sample std over seeds.\n\n"
    )
    tracking.end_sweep_run(
        uri,
        parent_id,
        {"finished": "FINISHED", "errored": "FAILED", "interrupted": "KILLED"}[status],
        header + summary + "\n",
    )
    _say("")
    _say(summary)
    _say("")
    _say(f"Tune results: {', '.join(tune_paths)}")
    _say(f"MLflow store: {uri} (experiment {spec.experiment!r}, parent run {parent_id})")
    _say(f"  mlflow ui --backend-store-uri {uri}")
    if interrupted:
        _say(f"interrupted: state saved. Resume with: python -m copilot_ray.sweep {spec.source} --resume")
    elif errored:
        _say(
            f"some trials failed; retry them from their last checkpoint with: "
            f"python -m copilot_ray.sweep {spec.source} --resume"
        )
    if own_ray:
        ray.shutdown()
    code = EXIT_INTERRUPTED if interrupted else (1 if errored else 0)
    return SweepOutcome(status, code, rows, summary, uri, parent_id, tune_paths, wall)


# ================================================================================================ CLI
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m copilot_ray.sweep", description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="sweep spec YAML (see copilot_ray/spec.py and sweeps/)")
    p.add_argument("--check", action="store_true", help="validate and print the plan; start nothing")
    p.add_argument("--resume", action="store_true", help="continue an interrupted or failed sweep")
    p.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    p.add_argument("--tracking-uri", default=None, help="MLflow tracking URI (default: the spec's)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from copilot_ray.spec import SpecError, load_spec

    try:
        spec = load_spec(args.spec)
    except SpecError as err:
        for line in err.problems:
            print(line, file=sys.stderr)
        return 2
    if args.check:
        print(spec.format_plan())
        return 0
    try:
        outcome = run_sweep(spec, resume=args.resume, address=args.address, tracking_uri=args.tracking_uri)
    except SweepError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return outcome.exit_code


if __name__ == "__main__":
    raise SystemExit(main())
