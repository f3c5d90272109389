"""MLflow wiring, in one place: where the store is, which metrics go there, and at which step.

Every curve is plotted against environment steps, so metrics are logged with
`step = num_env_steps_sampled_lifetime` (``keys.ENV_STEPS``). No Ray import: the Tune callback that drives
``TrialRuns`` is ``copilot_ray.tune_runtime.MlflowSweepCallback``.
"""

from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from copilot_ray import mlflow_view
from copilot_ray.keys import (
    ALGORITHM_TAG,
    ALPHA_SCHEDULE_TAG,
    B_TAG,
    CHECKPOINT_ARTIFACT,
    CONFIG_ARTIFACT,
    CONFIG_KEY_TAG,
    CONFIGURATION_TAG,
    ENV_STEPS,
    ENV_TAG,
    ERROR_ARTIFACT,
    ERROR_TAG,
    GIT_COMMIT_TAG,
    K_TAG,
    PARENT_TAG,
    PRESET_TAG,
    PRIVILEGES_TAG,
    ROLE_SWEEP,
    ROLE_TAG,
    ROLE_TRIAL,
    SEED_ERRORS,
    SEED_PARAM,
    SEED_RESULTS,
    SEED_TAG,
    SUMMARY_ARTIFACT,
    SWEEP_TAG,
    TIME_TOTAL_S,
    TRACKED_PREFIXES,
    TRAINING_ITERATION,
    TREES_DIR,
    TRIAL_ID_TAG,
    VARIANT_TAG,
    is_rllib_internal,
    result_value,
)
from copilot_ray.mlflow_view import configuration
from copilot_ray.privileges import tag_value
from copilot_ray.settings import logged_text
from copilot_ray.store import missing_sqlite_file
from copilot_ray.trials.description import (
    describe_trial,
    env_params,
    seed_config,
    stacked_seeds,
    trial_config_yaml,
)


def flatten(d: Mapping[str, Any], prefix: str = "", sep: str = "/") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in d.items():
        name = f"{prefix}{sep}{key}" if prefix else str(key)
        if isinstance(value, Mapping):
            out.update(flatten(value, name, sep))
        else:
            out[name] = value
    return out


def metrics_from_result(
    result: Mapping[str, Any], rllib_timers: bool = False, keep_nan: bool = False
) -> dict[str, float]:
    """The numeric metrics worth tracking from an RLlib result dict (flattened with '/'); RLlib's own
    timers and throughputs only with `rllib_timers`; NaN values (a figure not measured yet) only with
    `keep_nan`."""
    flat = flatten(result)
    out = {}
    for key, value in flat.items():
        if not key.startswith(TRACKED_PREFIXES) or (not rllib_timers and is_rllib_internal(key)):
            continue
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue
        if value != value and not keep_nan:  # NaN: MLflow accepts it, but it breaks the UI's comparisons
            continue
        out[key] = float(value)
    return out


def git_commit(checkout: str | Path | None = None) -> str:
    """HEAD of `checkout` (default: the one this package runs from), or "" outside git."""
    try:
        root = Path(__file__).resolve().parent.parent if checkout is None else Path(checkout)
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=5
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def params_for_mlflow(config: Mapping[str, Any]) -> dict[str, str]:
    """Flattened params, each value cut to MLflow's limit by `logged_text` (the full config is an artifact)."""
    return {key[:250]: logged_text(value) for key, value in flatten(config, sep=".").items()}


class MlflowRun:
    """A thin context manager around one MLflow run (used by `copilot_ray.train`)."""

    def __init__(self, tracking_uri: str, experiment: str, run_name: str, tags: Mapping[str, str]):
        self.client = _client(tracking_uri)
        exp_id = ensure_experiment(self.client, experiment)  # (marked as model training, as a sweep's)
        self.run = self.client.create_run(exp_id, run_name=run_name, tags=dict(tags))
        self.run_id = self.run.info.run_id

    @classmethod
    def reopen(cls, tracking_uri: str, run_id: str) -> MlflowRun:
        """The run `run_id` of the store, RUNNING again (`train --resume`: the run goes on in it)."""
        self = cls.__new__(cls)
        self.client = _client(tracking_uri)
        self.run = self.client.get_run(run_id)
        self.run_id = run_id
        self.client.update_run(run_id, status="RUNNING")
        return self

    def log_params(self, params: Mapping[str, str]) -> None:
        from mlflow.entities import Param

        items = [Param(k, v) for k, v in params.items()]
        for i in range(0, len(items), 100):
            self.client.log_batch(self.run_id, params=items[i : i + 100])

    def log_metrics(self, metrics: Mapping[str, float], step: int) -> None:

        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        items = [Metric(k, v, now, step) for k, v in metrics.items()]
        for i in range(0, len(items), 500):
            self.client.log_batch(self.run_id, metrics=items[i : i + 500])

    def log_artifacts(self, path: str | Path, artifact_path: str | None = None) -> None:
        self.client.log_artifacts(self.run_id, str(path), artifact_path)

    def log_artifact(self, path: str | Path, artifact_path: str | None = None) -> None:
        self.client.log_artifact(self.run_id, str(path), artifact_path)

    def end(self, status: str = "FINISHED") -> None:
        self.client.set_terminated(self.run_id, status=status)


# ================================================================================================ sweeps
# What a sweep writes to MLflow (copilot_ray.sweep), in one place (the names: copilot_ray.keys):
#
#   parent run (one per sweep)   tags  copilot.sweep=<name>, copilot.role=sweep, copilot.tune_path,
#                                      git_commit, mlflow.runName=<name>
#                                params  the sweep's shape (algorithm, env, searcher, seeds, trials, stop)
#                                artifacts  spec.yaml (as given), spec.resolved.yaml (what ran), summary.md
#   experiment                   tags  mlflow.sharedViewState.trials: the view its printed link opens
#                                      (copilot_ray.mlflow_view), mlflow.experimentKind, mlflow.note.content
#   child run (one per trial)    tags  mlflow.parentRunId, copilot.role=trial, copilot.sweep,
#                                      copilot.trial_id, copilot.config_key, copilot.configuration
#                                      ("<algorithm> <config key>"), algorithm, env, K, b,
#                                      alpha_schedule, preset, variant, copilot.privileges, seed,
#                                      git_commit; run name "<configuration> seed <seed>"
#                                params  every setting of the algorithm at its effective value, seed, env.*
#                                metrics  metrics_from_result + time_total_s + training_iteration,
#                                         step = env steps (keys.ENV_STEPS)
#                                artifacts  config.yaml, checkpoint/ (final), copilot_trees/*.npz


def _client(tracking_uri: str):
    import mlflow

    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
    return mlflow.MlflowClient(tracking_uri)


# The experiment's kind, as MLflow 3's UI offers to set it ("Machine learning"). MLflow 3.17's UI reads
# it only with its workflow switch off, and that switch is on in every build (its GenAI / model-training
# choice comes from the address's `workflowType`, else the browser's stored choice, else GenAI:
# copilot_ray/mlflow_app.py serves the model-training default); set all the same, for the UIs that read it.
EXPERIMENT_KIND_TAG, MODEL_TRAINING = "mlflow.experimentKind", "custom_model_development"
NOTE_TAG = "mlflow.note.content"  # an experiment's or a run's description in the UI


def ensure_experiment(
    client, name: str, artifact_location: str | None = None, description: str | None = None
) -> str:
    """The experiment's id, creating it (with ``artifact_location`` for a local store) if needed, marked
    as model training (the UI opens on its runs) and described by `description` unless it has a note."""
    exp = client.get_experiment_by_name(name)
    if exp is not None:
        if exp.lifecycle_stage == "deleted":
            client.restore_experiment(exp.experiment_id)
        exp_id, tags = exp.experiment_id, exp.tags
    else:
        exp_id, tags = client.create_experiment(name, artifact_location=artifact_location), {}
    if tags.get(EXPERIMENT_KIND_TAG) != MODEL_TRAINING:
        client.set_experiment_tag(exp_id, EXPERIMENT_KIND_TAG, MODEL_TRAINING)
    if description and NOTE_TAG not in tags:
        client.set_experiment_tag(exp_id, NOTE_TAG, description.strip())
    return exp_id


def local_artifact_location(tracking_uri: str, directory: str | Path) -> str | None:
    """A file: artifact root next to a local (sqlite / file) store; None for a tracking server.

    MLflow's default artifact root for a sqlite store is ``./mlruns`` relative to the working directory
    of whoever creates the experiment; pinning it keeps a sweep's artifacts in its own folder.
    """
    if tracking_uri.startswith(("sqlite:", "file:")) or "://" not in tracking_uri:
        return Path(directory).resolve().as_uri()
    return None


def _quote(value: str) -> str:
    return "'" + str(value).replace("\\", "\\\\").replace("'", "\\'") + "'"


def find_runs(client, experiment_id: str, tags: Mapping[str, str]) -> list:
    """Runs of the experiment carrying all ``tags`` (oldest first)."""
    filt = " and ".join(f"tags.`{k}` = {_quote(v)}" for k, v in tags.items())
    runs, token = [], None
    while True:
        page = client.search_runs(
            [experiment_id],
            filter_string=filt,
            max_results=1000,
            page_token=token,
            order_by=["attributes.start_time ASC"],
        )
        runs.extend(page)
        token = page.token
        if not token:
            return runs


def open_sweep_run(
    tracking_uri: str,
    experiment: str,
    sweep: str,
    *,
    resume: bool,
    tags: Mapping[str, str] = (),
    params: Mapping[str, Any] = (),
    artifact_location: str | None = None,
    description: str | None = None,
) -> tuple[str, str, bool]:
    """The sweep's parent run: ``(experiment_id, run_id, reused)``.

    ``resume``: reuse the newest parent run tagged ``copilot.sweep=<sweep>, copilot.role=sweep`` (set
    back to RUNNING); a new one is created when there is none. Otherwise always a new parent run.
    """
    client = _client(tracking_uri)
    exp_id = ensure_experiment(client, experiment, artifact_location, description)
    if resume:
        found = find_runs(client, exp_id, {SWEEP_TAG: sweep, ROLE_TAG: ROLE_SWEEP})
        if found:
            run_id = found[-1].info.run_id
            client.update_run(run_id, status="RUNNING")
            return exp_id, run_id, True
    note = {NOTE_TAG: description.strip()} if description else {}
    run = client.create_run(
        exp_id,
        run_name=sweep,
        tags={SWEEP_TAG: sweep, ROLE_TAG: ROLE_SWEEP, GIT_COMMIT_TAG: git_commit(), **note, **dict(tags)},
    )
    run_id = run.info.run_id
    if params:
        _log_params(client, run_id, params_for_mlflow(dict(params)))
    return exp_id, run_id, False


def show_trials(tracking_uri: str, experiment_id: str, configurations, columns, chart_metrics) -> None:
    """Sets the experiment's view of its trials (copilot_ray.mlflow_view), adding to the one an earlier
    part of the sweep file set."""
    client = _client(tracking_uri)
    earlier = mlflow_view.decode(client.get_experiment(experiment_id).tags.get(mlflow_view.VIEW_TAG))
    view = mlflow_view.trials_view(configurations, columns, chart_metrics, earlier)
    client.set_experiment_tag(experiment_id, mlflow_view.VIEW_TAG, mlflow_view.encode(view))


def sweep_runs_in_store(tracking_uri: str, experiment: str, sweep: str) -> tuple[str | None, list[str]]:
    """What the store holds of a sweep: ``(finished parent run id or None, ids of every run it holds)``.

    A store copied to another machine without Tune's folders (a long comparison carried from one session
    to the next) tells ``--resume`` which parts are done; it opens an existing SQLite file only."""
    if missing_sqlite_file(tracking_uri) is not None:
        return None, []
    client = _client(tracking_uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        return None, []
    everything = find_runs(client, exp.experiment_id, {SWEEP_TAG: sweep})
    parents = [r for r in everything if r.data.tags.get(ROLE_TAG) == ROLE_SWEEP]
    finished = parents[-1].info.run_id if parents and parents[-1].info.status == "FINISHED" else None
    return finished, [r.info.run_id for r in everything]


def trial_runs_in_store(tracking_uri: str, experiment: str, sweep: str) -> list:
    """The trial (child) runs of a sweep in the store, oldest first; [] when there is no such store or
    experiment (nothing has run). Opens an existing SQLite file only."""
    if missing_sqlite_file(tracking_uri) is not None:
        return []
    client = _client(tracking_uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        return []
    return find_runs(client, exp.experiment_id, {SWEEP_TAG: sweep, ROLE_TAG: ROLE_TRIAL})


def metric_history(tracking_uri: str, run_id: str, key: str) -> list[tuple[int, float]]:
    """A run's values of metric `key` as (step, value), in step order (our runs log at env steps)."""
    return sorted((m.step, m.value) for m in _client(tracking_uri).get_metric_history(run_id, key))


def discard_runs(tracking_uri: str, run_ids: Sequence[str]) -> None:
    """Marks runs deleted (MLflow's soft delete: reports, best_of and the UI's default view skip them)."""
    client = _client(tracking_uri)
    for run_id in run_ids:
        client.delete_run(run_id)


def end_sweep_run(
    tracking_uri: str,
    run_id: str,
    status: str,
    summary_md: str | None = None,
    summary_metrics: Mapping[str, float] | None = None,
    step: int = 0,
) -> None:
    """Closes the sweep's parent run with its summary: the table as an artifact, and per configuration
    its figures as metrics (so the parent row in MLflow's runs list shows the sweep's outcome), at
    `step` (the env steps its trials have taken: each stop's summary is a point of its own, never a
    second entry at one step). A figure the run already holds with the same value is not logged again:
    --resume closes a finished part once more, and its history should keep one entry."""
    client = _client(tracking_uri)
    if summary_md is not None:
        client.log_text(run_id, summary_md, SUMMARY_ARTIFACT)
    if summary_metrics:
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        held = client.get_run(run_id).data.metrics
        items = [
            Metric(k, float(v), now, int(step)) for k, v in summary_metrics.items() if held.get(k) != float(v)
        ]
        for i in range(0, len(items), 500):
            client.log_batch(run_id, metrics=items[i : i + 500])
    client.set_terminated(run_id, status=status)


def log_sweep_files(tracking_uri: str, run_id: str, files: Mapping[str, str | Path]) -> None:
    """``{artifact name: local file}`` onto the parent run (overwrites on resume)."""
    client = _client(tracking_uri)
    for name, path in files.items():
        client.log_text(run_id, Path(path).read_text(), name)


def _log_params(client, run_id: str, params: Mapping[str, str]) -> None:
    from mlflow.entities import Param

    items = [Param(k, v) for k, v in params.items()]
    for i in range(0, len(items), 100):
        client.log_batch(run_id, params=items[i : i + 100])


# ------------------------------------------------------------------------------- a sweep's child runs
def result_metrics(
    result: Mapping[str, Any], rllib_timers: bool = False, keep_nan: bool = False
) -> dict[str, float]:
    """What a trial logs per result: ``metrics_from_result`` plus Tune's wall time and iteration."""
    metrics = metrics_from_result(result, rllib_timers, keep_nan)
    for key in (TIME_TOTAL_S, TRAINING_ITERATION):
        if isinstance(result.get(key), int | float):
            metrics[key] = float(result[key])
    return metrics


class TrialRuns:
    """One MLflow child run per Tune trial under the sweep's parent run (see the table above); a stacked
    trial (spec `seeds_per_trial` > 1) gets one run per seed, each tagged and logged as a one-seed trial's
    run would be (its seed's metrics from the result's `keys.SEED_RESULTS`), and a seed that failed ends
    FAILED on its own with its error (`keys.SEED_ERRORS`) while the others go on.

    ``copilot_ray.tune_runtime.MlflowSweepCallback`` calls it from Tune's hooks; ``trial`` is a Tune
    trial (``trial_id``, ``config``, ``status``, ``last_result``, ``checkpoint``, ``error_file``, ...).
    Stateless across a resume: a trial's run is found again by its ``copilot.trial_id`` tag (and its
    seed's, in a stack), and metric rows whose step (env steps) is <= the largest step already logged for
    that run are skipped (a trial restored from a checkpoint replays the iterations after it). Pickled
    without its caches.
    """

    _STATE = ("tracking_uri", "experiment_id", "sweep", "parent_run_id", "rllib_timers")

    def __init__(
        self,
        tracking_uri: str,
        experiment_id: str,
        sweep: str,
        parent_run_id: str,
        rllib_timers: bool = False,
    ):
        self.tracking_uri = tracking_uri
        self.experiment_id = experiment_id
        self.sweep = sweep
        self.parent_run_id = parent_run_id
        self.rllib_timers = rllib_timers
        self._reset()

    def _reset(self) -> None:
        self._client_obj = None
        self._runs: dict[tuple[str, int | None], str] = {}  # (tune trial id, stacked seed) -> mlflow run id
        self._last_step: dict[str, int] = {}  # mlflow run id -> largest step logged
        self._failed: set[str] = set()  # runs of stacked seeds already ended FAILED
        self._commit: str | None = None

    def __getstate__(self):
        return {k: self.__dict__[k] for k in self._STATE}

    def __setstate__(self, state):
        self.__dict__.update({"rllib_timers": False, **state})
        self._reset()

    @property
    def client(self):
        if self._client_obj is None:
            self._client_obj = _client(self.tracking_uri)
        return self._client_obj

    # ---------------------------------------------------------------------- the run of a trial
    @staticmethod
    def seeds_of(trial) -> list[int | None]:
        """The seeds a trial has a run for: a stacked trial's, else [None] (its one run)."""
        return stacked_seeds(trial.config or {}) or [None]

    def open(self, trial) -> None:
        """The trial's run(s), created or found again (a stacked trial: one per seed)."""
        for seed in self.seeds_of(trial):
            self.run_id(trial, seed)

    def run_id(self, trial, seed: int | None = None) -> str:
        """The trial's run (`seed`: a stacked seed's): cached, else found again (resume), else created."""
        key = (trial.trial_id, seed)
        run_id = self._runs.get(key)
        if run_id is None:
            run_id = self._find_run(trial, seed)
            if run_id is None:
                run_id = self._create_run(trial, seed)
                self._last_step[run_id] = -1
            self._runs[key] = run_id
        return run_id

    def _find_run(self, trial, seed: int | None) -> str | None:
        tags = {PARENT_TAG: self.parent_run_id, TRIAL_ID_TAG: trial.trial_id}
        if seed is not None:
            tags[SEED_TAG] = str(seed)
        found = find_runs(self.client, self.experiment_id, tags)
        if not found:
            return None
        run_id = found[0].info.run_id
        if seed is not None and found[0].info.status == "FAILED":
            self._failed.add(run_id)  # a stacked seed that failed stays ended (its trial goes on)
        elif found[0].info.status != "RUNNING":
            self.client.update_run(run_id, status="RUNNING")
        history = self.client.get_metric_history(run_id, TRAINING_ITERATION)
        self._last_step[run_id] = max((m.step for m in history), default=-1)
        return run_id

    def _create_run(self, trial, seed: int | None) -> str:
        info = describe_trial(trial.config if seed is None else seed_config(trial.config, seed))
        # what the row says in MLflow's table: the configuration and the seed
        name = f"{configuration(info['algorithm'], info['config_key'])} seed {info['seed']}"
        run = self.client.create_run(self.experiment_id, run_name=name, tags=self._tags(trial, info))
        run_id = run.info.run_id
        # (params and tags agree: the preset a run used is "default" when none was named)
        params = {
            **info["settings"],
            **({"preset": info["preset"]} if "preset" in info["settings"] else {}),
            SEED_PARAM: info["seed"],
            **env_params(info["spec"], info["env"]),
        }
        _log_params(self.client, run_id, params_for_mlflow(params))
        self.client.log_text(run_id, trial_config_yaml(info), CONFIG_ARTIFACT)
        return run_id

    def _tags(self, trial, info: Mapping[str, Any]) -> dict[str, str]:
        if self._commit is None:
            self._commit = git_commit()
        return {
            PARENT_TAG: self.parent_run_id,
            ROLE_TAG: ROLE_TRIAL,
            SWEEP_TAG: self.sweep,
            TRIAL_ID_TAG: trial.trial_id,
            CONFIG_KEY_TAG: info["config_key"],
            CONFIGURATION_TAG: configuration(info["algorithm"], info["config_key"]),
            ALGORITHM_TAG: info["algorithm"],
            ENV_TAG: info["env"],
            **{tag: str(info[key]) for tag, key in ((K_TAG, "K"), (B_TAG, "b")) if info[key] is not None},
            ALPHA_SCHEDULE_TAG: info["alpha_schedule"],
            PRESET_TAG: info["preset"],
            VARIANT_TAG: info["variant"],
            PRIVILEGES_TAG: tag_value(info["privileges"]),
            SEED_TAG: str(info["seed"]),
            GIT_COMMIT_TAG: self._commit,
        }

    # ---------------------------------------------------------------------- what happens to it
    def log_result(self, trial, result: Mapping[str, Any]) -> None:
        """One metric row at step = env steps, unless a run restored from a checkpoint logged it already;
        a stacked trial: a row per seed, and a seed that failed ends FAILED now."""
        per_seed = result.get(SEED_RESULTS)
        if per_seed is None:
            step = int(result_value(result, ENV_STEPS, 0))
            self._log_row(self.run_id(trial), result_metrics(result, self.rllib_timers), step)
            return
        for seed, metrics in sorted(per_seed.items()):
            kept = {k: v for k, v in metrics.items() if self.rllib_timers or not is_rllib_internal(k)}
            self._log_row(self.run_id(trial, int(seed)), kept, int(metrics.get(ENV_STEPS, 0)))
        for seed, error in sorted((result.get(SEED_ERRORS) or {}).items()):
            run_id = self.run_id(trial, int(seed))
            if run_id not in self._failed:
                self.client.set_tag(run_id, ERROR_TAG, str(error)[:300] or "(no message)")
                self.client.set_terminated(run_id, status="FAILED")
                self._failed.add(run_id)

    def _log_row(self, run_id: str, metrics: Mapping[str, float], step: int) -> None:
        if step <= self._last_step.get(run_id, -1):
            return
        self._log_metrics(run_id, metrics, step)
        self._last_step[run_id] = step

    def _log_metrics(self, run_id: str, metrics: Mapping[str, float], step: int) -> None:

        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        items = [Metric(k, v, now, step) for k, v in metrics.items()]
        for i in range(0, len(items), 500):
            self.client.log_batch(run_id, metrics=items[i : i + 500])

    def finish(self, trial, status: str) -> None:
        """The final checkpoint, the sub-goal trees (and the error) as artifacts; the run(s) end
        ``status`` (a stacked seed that failed stays FAILED)."""
        failed = {str(s) for s in ((trial.last_result or {}).get(SEED_ERRORS) or {})}
        for seed in self.seeds_of(trial):
            run_id = self.run_id(trial, seed)
            own = "FAILED" if str(seed) in failed else status
            try:
                self._log_final_artifacts(run_id, trial, own, seed)
            finally:
                self.client.set_terminated(run_id, status=own)
                self._runs.pop((trial.trial_id, seed), None)

    def _log_final_artifacts(self, run_id: str, trial, status: str, seed: int | None) -> None:
        checkpoint = trial.checkpoint
        if checkpoint is not None and Path(checkpoint.path).is_dir():
            path = Path(checkpoint.path) if seed is None else Path(checkpoint.path) / f"seed_{seed}"
            if path.is_dir():
                self.client.log_artifacts(run_id, str(path), CHECKPOINT_ARTIFACT)
        for tree_dir in _tree_dirs(trial, seed):
            self.client.log_artifacts(run_id, str(tree_dir), TREES_DIR)
            break
        error_file = getattr(trial, "error_file", None)
        if status == "FAILED" and error_file and Path(error_file).is_file():
            self.client.log_artifact(run_id, error_file, ERROR_ARTIFACT)
            self.client.set_tag(run_id, ERROR_TAG, error_reason(error_file) or "(no message)")

    def kill_unfinished(self, trials) -> None:
        """Interrupted (Ctrl-C / SIGTERM): runs of unfinished trials wait, KILLED, for --resume."""
        for trial in trials:
            done = trial.status == "ERROR" or (trial.last_result or {}).get("done")
            if done:  # (cleanup marks stopped trials TERMINATED)
                continue
            for seed in self.seeds_of(trial):
                run_id = self._runs.get((trial.trial_id, seed))
                if run_id is not None and run_id not in self._failed:
                    self.client.set_terminated(run_id, status="KILLED")


def error_reason(error_file: str | None, limit: int = 300) -> str:
    """The last line of a Tune trial's error file: the exception and its message ("" without one)."""
    try:
        lines = [line.strip() for line in Path(error_file).read_text().splitlines() if line.strip()]
    except (OSError, TypeError):
        return ""
    return lines[-1][:limit] if lines else ""


def _tree_dirs(trial, seed: int | None = None) -> list[Path]:
    """Where a trial's ``copilot_trees/`` can be: the synced trial dir, or the local working dir (a
    stacked seed's: their ``seed_<s>/`` folder).

    ``Algorithm.logdir`` of a Tune trial is Tune's per-trial *working directory* under the Ray session
    (``/tmp/ray/session_*/artifacts/<time>/<experiment>/working_dirs/<trial>``); the sweep syncs it into
    the trial folder (``SyncConfig(sync_artifacts=True)``) on every checkpoint.
    """
    out = []
    candidates = [trial.path]
    try:
        candidates.append(trial.storage.trial_working_directory)
    except Exception:  # noqa: BLE001 - no storage context: nothing to look at
        pass
    if seed is not None:
        candidates = [None if base is None else str(Path(base) / f"seed_{seed}") for base in candidates]
    for base in candidates:
        if base and (Path(base) / TREES_DIR).is_dir() and any((Path(base) / TREES_DIR).iterdir()):
            out.append(Path(base) / TREES_DIR)
    return out
