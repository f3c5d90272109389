"""The Ray side of a sweep: the Tune trainable, the Tune callbacks, the Tuner.

Importing this module imports Ray (and RLlib, torch): ``copilot_ray.sweep`` imports it only once a spec is
validated, so that a bad spec and ``--check`` never start Ray. Tune pickles the trainable, the callbacks
and the searcher's space by reference to this module; Ray's workers import it to unpickle them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import ray
from ray import tune
from ray.tune import Callback

from copilot_ray.keys import (
    ENV_STEPS,
    EVAL_FRESH,
    PATH_LENGTH_VS_RRT,
    PATH_SUCCESS,
    SEED_ERRORS,
    SEED_PARAM,
    SPEC_PATH_KEY,
    SUCCESS_METRICS,
    TIME_TOTAL_S,
    TRAINING_ITERATION,
    result_value,
    validation_key,
)
from copilot_ray.registry import get_algorithm
from copilot_ray.sweep_spec import (
    default_point,
    optuna_define_by_run,
    to_tune_scheduler,
    to_tune_search_space,
    tune_stop,
)
from copilot_ray.tracking import TrialRuns, error_reason
from copilot_ray.trials.description import describe_trial, load_spec_cached


def trainable(spec) -> type:
    """The trial class of the spec's algorithm (the registry's third entry), or the stacked-seeds trial
    for `seeds_per_trial` > 1."""
    if spec.seeds_per_trial > 1:
        from copilot_ray.algorithms.sac.trial import SeedStackTrial

        return SeedStackTrial
    return get_algorithm(spec.algorithm).trial_class()


class ProgressPrinter(Callback):
    """One line per trial event; replaces Tune's table (which dumps the whole RLlib config)."""

    _FIELDS = ("config_key", "algorithm", "env", "K", "b", "alpha_schedule", "seed")

    def __init__(self):
        self._info: dict[str, dict[str, Any]] = {}
        self._stopped: set[tuple[str, str]] = set()  # (trial, seed) of stacked seeds said to have stopped

    def __getstate__(self):
        return {}

    def __setstate__(self, state):
        self._info, self._stopped = {}, set()

    def _head(self, trial) -> str:
        info = self._info.get(trial.trial_id)
        if info is None:
            info = self._info[trial.trial_id] = self._describe(trial.config)
        if info["algorithm"] != "copilot":  # name the algorithm and the env instead
            depth = f" K={info['K']}" if isinstance(info["K"], int) and info["K"] > 0 else ""
            return (
                f"[{trial.trial_id}] {info['config_key']:<18} {info['algorithm']} on {info['env']}{depth} "
                f"seed={info['seed']}"
            )
        return (
            f"[{trial.trial_id}] {info['config_key']:<18} K={info['K']} b={info['b']} "
            f"alpha={info['alpha_schedule']} seed={info['seed']}"
        )

    @classmethod
    def _describe(cls, config: Mapping[str, Any]) -> dict[str, Any]:
        try:
            d = describe_trial(config)
            return {k: d[k] for k in cls._FIELDS}
        except Exception as err:  # noqa: BLE001 - a progress line must not fail the sweep
            return {**dict.fromkeys(cls._FIELDS, "?"), "config_key": f"? ({err})"}

    def on_trial_start(self, iteration, trials, trial, **info):
        _say(f"{self._head(trial)}  started")

    def on_trial_result(self, iteration, trials, trial, result, **info):
        # The validation tasks' figures: what one may watch (and choose by) while a sweep runs; the test
        # tasks' are the report's.
        success, planned, direct = (result_value(result, validation_key(k)) for k in SUCCESS_METRICS)
        steps = result_value(result, ENV_STEPS, 0)
        mark = "" if result_value(result, EVAL_FRESH, 1.0) else " (last eval)"
        if success is None:  # a planner-only baseline: its paths' figures
            figures = (
                f"paths success {_fmt(result_value(result, PATH_SUCCESS))} "
                f"length/RRT* {_fmt(result_value(result, PATH_LENGTH_VS_RRT))}"
            )
        elif planned is None:
            figures = f"validation success {_fmt(success)}{mark}"
        else:
            figures = (
                f"validation success {_fmt(success)} (planned {_fmt(planned)} direct {_fmt(direct)}){mark}"
            )
        _say(
            f"{self._head(trial)}  iter {result.get(TRAINING_ITERATION, 0):4d}  "
            f"env_steps {int(steps):8d}  {figures}  {result.get(TIME_TOTAL_S, 0.0):7.1f}s"
        )
        for seed, error in (result.get(SEED_ERRORS) or {}).items():
            if (trial.trial_id, seed) not in self._stopped:
                self._stopped.add((trial.trial_id, seed))
                _say(f"{self._head(trial)}  seed {seed} stopped ({error}); the other seeds go on")

    def on_trial_complete(self, iteration, trials, trial, **info):
        _say(f"{self._head(trial)}  done")

    def on_trial_recover(self, iteration, trials, trial, **info):
        reason = error_reason(trial.error_file) or "(no message)"
        _say(f"{self._head(trial)}  failed ({reason}), retrying from its last checkpoint")

    def on_trial_error(self, iteration, trials, trial, **info):
        reason = error_reason(trial.error_file)
        _say(f"{self._head(trial)}  ERROR: {reason or '(no message)'}; details: {trial.error_file}")


def _say(line: str) -> None:
    print(line, flush=True)


def _fmt(v: Any) -> str:
    return f"{v:.2f}" if isinstance(v, int | float) and not math.isnan(v) else "  - "


class MlflowSweepCallback(Callback):
    """One MLflow child run per Tune trial under the sweep's parent run: Tune's hooks, handed to
    ``copilot_ray.tracking.TrialRuns``."""

    def __init__(
        self,
        tracking_uri: str,
        experiment_id: str,
        sweep: str,
        parent_run_id: str,
        rllib_timers: bool = False,
    ):
        self.runs = TrialRuns(tracking_uri, experiment_id, sweep, parent_run_id, rllib_timers)

    def on_trial_start(self, iteration, trials, trial, **info):
        self.runs.open(trial)

    def on_trial_result(self, iteration, trials, trial, result, **info):
        self.runs.log_result(trial, result)

    def on_trial_complete(self, iteration, trials, trial, **info):
        self.runs.finish(trial, "FINISHED")

    def on_trial_error(self, iteration, trials, trial, **info):
        self.runs.finish(trial, "FAILED")

    def on_experiment_end(self, trials, **info):
        self.runs.kill_unfinished(trials)


# ================================================================================================ Tuner
def start_ray(address: str | None) -> bool:
    """Starts Ray unless one is running (``address``: connect to that cluster); True when started here."""
    if ray.is_initialized():
        return False
    if address:
        # A cluster's workers were started by `ray start`, not by this process: pass the waiting policy on.
        env_vars = {"OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY", "PASSIVE")}
        ray.init(address=address, log_to_driver=False, runtime_env={"env_vars": env_vars})
    else:
        # "local": a Ray of our own even where RAY_ADDRESS is set or `ray start` left a cluster running on
        # this machine; Ray would attach to those and then refuse num_cpus (--address picks a cluster).
        ray.init(address="local", num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False)
    return True


def stop_ray() -> None:
    ray.shutdown()


def cluster_cpus(address: str) -> int:
    """The CPUs of the running cluster at `address` (connects, reads, disconnects)."""
    ray.init(address=address, log_to_driver=False)
    try:
        return int(ray.cluster_resources().get("CPU", 0))
    finally:
        ray.shutdown()


def restore_tuner(spec, path: Path) -> tune.Tuner | None:
    """The Tune experiment at ``path`` to continue (errored trials too), or None when there is none."""
    if not (path.exists() and tune.Tuner.can_restore(str(path))):
        return None
    return tune.Tuner.restore(str(path), trainable=trainable(spec), resume_errored=True)


def build_tuner(
    spec, spec_path: Path, root: Path, exp_name: str, seed: int | None, index: int, callbacks: list
) -> tune.Tuner:
    """A fresh Tune experiment ``exp_name`` under ``root/tune``: the grid, or seed ``seed``'s Optuna study."""

    if spec.searcher.type == "grid":
        param_space = {**to_tune_search_space(spec), SPEC_PATH_KEY: str(spec_path)}
        search_alg, num_samples = None, 1
    else:
        param_space = {SEED_PARAM: seed, SPEC_PATH_KEY: str(spec_path)}
        search_alg = _searcher(spec, spec_path, root / "optuna.db", index, seed)
        num_samples = spec.searcher.num_samples
    return tune.Tuner(
        trainable(spec),
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
            storage_path=str(root / "tune"),
            stop=tune_stop(spec),
            # (the synced copilot_trees/ follow the checkpoints)
            checkpoint_config=tune.CheckpointConfig(
                checkpoint_frequency=spec.fault_tolerance.checkpoint_every,
                checkpoint_at_end=True,
                num_to_keep=2,
            ),
            failure_config=tune.FailureConfig(max_failures=spec.fault_tolerance.max_failures),
            # copilot_trees/ is written to the trial's working dir; sync it into the trial folder.
            sync_config=tune.SyncConfig(sync_artifacts=True),
            callbacks=callbacks,
            verbose=0,
        ),
    )


def _searcher(spec, spec_path: Path, study_db: Path, index: int, seed: int):
    import optuna
    from ray.tune.search.optuna import OptunaSearch

    s = spec.searcher
    sampler_seed = (s.seed or 0) + index
    sampler = {
        "tpe": lambda: optuna.samplers.TPESampler(seed=sampler_seed),
        "random": lambda: optuna.samplers.RandomSampler(seed=sampler_seed),
        "cmaes": lambda: optuna.samplers.CmaEsSampler(seed=sampler_seed),
    }[s.sampler or "tpe"]()
    first = default_point(spec)
    return OptunaSearch(
        space=OptunaSpace(str(spec_path)),
        metric=s.metric,
        mode=s.mode,
        points_to_evaluate=[first] if first else None,  # the defaults always compete
        sampler=sampler,
        study_name=f"{spec.name}-seed{seed}",
        storage=optuna.storages.RDBStorage(f"sqlite:///{study_db}"),
    )


class OptunaSpace:
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
            self._fn = optuna_define_by_run(load_spec_cached(self.spec_path))
        return self._fn(trial)
