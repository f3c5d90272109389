"""MLflow -> plain Python/numpy structures for one sweep.

The layout read here is the sweep runner's contract (ARCHITECTURE.md, "Metrics", and `copilot_ray.sweep`): one
parent run per sweep (tag `copilot.role=sweep`), one child run per trial (tags `mlflow.parentRunId`,
`copilot.role=trial`, `copilot.config_key`, `seed`, the axis tags `algorithm`, `env`, `variant`, `preset`, `K`, `b`,
`alpha_schedule`; params `env.id`, `env.config.<key>` and every setting), success metrics logged with
`step` = environment steps, and sub-goal tree snapshots as `copilot_trees/trees_iterNNNNNN.npz` artifacts.

Configurations are not seeds (`configurations`): runs are one configuration only when algorithm, config key,
env id, env config and every other logged param (the settings' effective values) agree; a seed that still
repeats within one is split by the sweep (parent) run. An env-config value or a param that differs between
configurations is an axis of the labels (`Sweep.axes`: ``layout=u-maze``).

Evaluation curves keep only real evaluations: a sweep trial logs every iteration and repeats its last
evaluation in between, marking the rows that evaluated with `copilot/eval/fresh` = 1 (`fresh_only`).
"""

from __future__ import annotations

import os
import sqlite3
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from copilot_ray.keys import (
    AGENT_SUBTASK_SUCCESS_LAYER,
    ALGORITHM_TAG,
    AXIS_TAGS,
    BUDGET_PARAM,
    CONFIG_KEY_TAG,
    CURVE_METRICS,
    DIAG_PREFIX,
    ENV_PARAM,
    ENV_STEPS,
    ENV_TAG,
    EVAL_FRESH,
    EVAL_PREFIX,
    PARENT_TAG,
    PATH_SUCCESS,
    PATHS_PREFIX,
    PRIVILEGE_COUNTS,
    REPORT_ARTIFACT,
    RESOLVED_SPEC_ARTIFACT,
    ROLE_SWEEP,
    ROLE_TAG,
    ROLE_TRIAL,
    SEARCHER_PARAM,
    SEARCHES,
    SEED_PARAM,
    SEED_TAG,
    SPEC_ARTIFACT,
    SUCCESS_METRICS,
    SWEEP_TAG,
    TIME_TOTAL_S,
    TREES_DIR,
    VALIDATION_PREFIX,
    validation_key,
)
from copilot_ray.store import missing_sqlite_file, tracking_uri_problem

# Curves for the diagnostics page (copilot_ray.planning.plan_diagnostics): every metric under these
# prefixes that a run logged.
DIAGNOSTIC_PREFIXES = (DIAG_PREFIX, EVAL_PREFIX, AGENT_SUBTASK_SUCCESS_LAYER)
# The pseudo-axis that labels configurations by their config key when no axis tag tells them apart.
CONFIG_KEY_AXIS = "config_key"
# Axes beyond the tags: an env-config key (ENV_CONFIG_PREFIX + key, shown as the key: "layout"), the sweep a
# run belongs to and its parent run (when one configuration ran in two sweeps), a param ("param:" + name).
ENV_CONFIG_PREFIX = "env.config."
SWEEP_AXIS = "sweep"
PARENT_AXIS = "sweep run"
PARAM_AXIS_PREFIX = "param:"
# The env-step evaluation cadence's setting (`Trial.eval_every`).
EVAL_EVERY_PARAM = "eval_every_env_steps"
# Params that differ from run to run of one configuration (never part of its identity).
PER_RUN_PARAMS = (SEED_PARAM, "checkpoint_dir")
# Statuses whose numbers enter the statistics: a RUNNING trial is a valid prefix of its curve; a FAILED or
# KILLED one is listed as missing instead (its last numbers are where it broke, not where it ended).
USABLE_STATUSES = ("FINISHED", "RUNNING")
# Metrics whose rows between evaluations are stale copies of the last evaluation (see `fresh_only`).
EVALUATION_PREFIXES = (EVAL_PREFIX, VALIDATION_PREFIX)


ALL_SWEEPS = "all"  # --parent-run all: the trials of every sweep run of the experiment
# Which tasks' evaluations a report shows. "auto": the validation tasks when every sweep of the report
# is a search (its parent run's SEARCHER_PARAM is one of SEARCHES: it chose by validation figures, so
# showing it test figures would invite choosing by them), else the test tasks.
TEST, VALIDATION, AUTO = "test", "validation", "auto"
TASK_SETS = (AUTO, TEST, VALIDATION)


class AnalysisError(Exception):
    """Bad input that the CLI reports as one clear line and exit status 2."""


@dataclass
class Trial:
    """One child run: its identity, tags, and the curves the report needs."""

    run_id: str
    run_name: str
    status: str
    config_key: str
    seed: str
    tags: dict[str, str]
    # metric key -> (env steps, values), sorted by step
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    wall_time_s: float = float("nan")
    tree_artifacts: list[str] = field(default_factory=list)
    tracking_uri: str = ""  # the store it came from (report --also-from: several stores)
    latest: dict[str, float] = field(default_factory=dict)  # every metric's last logged value
    # MLflow params: env.id, env.config.*, the settings' effective values, seed
    params: dict[str, str] = field(default_factory=dict)
    budget: float = float("nan")  # its sweep's env-step budget (parent param stop.env_steps); NaN: none

    @property
    def env_id(self) -> str:
        return self.params.get(ENV_PARAM) or self.tags.get(ENV_TAG, "")

    @property
    def env_config(self) -> dict[str, str]:
        """`env.config.<key>` params: the env's config (e.g. its layout)."""
        n = len(ENV_CONFIG_PREFIX)
        return {k[n:]: v for k, v in self.params.items() if k.startswith(ENV_CONFIG_PREFIX)}

    @property
    def env_steps(self) -> float:
        """Env steps at the last logged result (older runs without the metric: the last curve step)."""
        if ENV_STEPS in self.latest:
            return float(self.latest[ENV_STEPS])
        ends = [steps[-1] for steps, _ in self.curves.values() if len(steps)]
        return float(max(ends)) if ends else float("nan")

    @property
    def eval_every(self) -> float:
        """Its env-step evaluation cadence (the setting `EVAL_EVERY_PARAM`): an evaluation runs at the end
        of the first iteration past each multiple of it. NaN: none logged (an iterations cadence, older
        runs)."""
        try:
            every = float(self.params.get(EVAL_EVERY_PARAM, "nan"))
        except ValueError:
            return float("nan")
        return every if every > 0 else float("nan")

    @property
    def usable(self) -> bool:
        return self.status in USABLE_STATUSES

    def curves_agree(self, a: str, b: str) -> bool:
        """Whether metrics `a` and `b` were both logged, at the same env steps, with the same values."""
        if a not in self.curves or b not in self.curves:
            return False
        (steps_a, values_a), (steps_b, values_b) = self.curves[a], self.curves[b]
        return np.array_equal(steps_a, steps_b) and np.allclose(values_a, values_b)

    @property
    def has_eval(self) -> bool:
        """Evaluated at least once: the agent's success, or (planner-only baselines) its paths'."""
        return any(len(self.curves.get(k, ((), ()))[0]) for k in (*SUCCESS_METRICS, PATH_SUCCESS))


@dataclass
class Sweep:
    tracking_uri: str
    experiment: str
    experiment_id: str
    parent_run_id: str | None
    sweep_name: str
    trials: list[Trial]
    other_parent_ids: list[str] = field(default_factory=list)
    # (tracking URI, run id, sweep name) of every sweep (parent) run whose trials are included
    parents: list[tuple[str, str, str]] = field(default_factory=list)
    tasks: str = TEST  # whose evaluations the trials' copilot/eval/ figures are (`on_validation_tasks`)
    joined_experiments: list[str] = field(default_factory=list)  # others whose runs `add_trials_from` added

    def axes(self) -> list[str]:
        """What the configuration labels name (`axis_value`): the axis tags and env-config keys that take more
        than one value among the child runs (an env-config key right after `env`); when those do not tell
        the configurations (`configurations`) apart, the algorithm (if it varies), the axis tags that differ
        within one algorithm's config key, the config key and the env-config axes, then the sweep, its run
        and the params that differ, until they do (e.g. an HPO sweep over planner knobs, one config key run
        in two sweeps on two layouts, or two presets' sweeps joined from two stores)."""
        trials = self.trials
        groups = list(configurations(trials).values())

        def varies(axis: str) -> bool:
            return len({axis_value(t, axis) for t in trials}) > 1

        def separates(axes: list[str]) -> bool:
            return len({tuple(axis_value(g[0], a) for a in axes) for g in groups}) == len(groups)

        env_axes = [
            ENV_CONFIG_PREFIX + k
            for k in sorted({k for t in trials for k in t.env_config})
            if varies(ENV_CONFIG_PREFIX + k)
        ]
        named: list[str] = []
        for tag in AXIS_TAGS:
            if varies(tag):
                named.append(tag)
            if tag == ENV_TAG:
                named += env_axes
        if len(groups) <= 1 or separates(named):
            return named

        def varies_within_a_config_key(tag: str) -> bool:
            seen: dict[tuple[str, str], set[str]] = {}
            for t in trials:
                seen.setdefault((axis_value(t, ALGORITHM_TAG), t.config_key), set()).add(axis_value(t, tag))
            return any(len(values) > 1 for values in seen.values())

        # a tag that differs between one algorithm's runs of one config key (e.g. two presets, each run in
        # a sweep of its own under the key "default") is named too: the config key alone would hide it
        tags_in_key = [
            t for t in AXIS_TAGS if t not in (ALGORITHM_TAG, ENV_TAG) and varies_within_a_config_key(t)
        ]
        axes = ([ALGORITHM_TAG] if varies(ALGORITHM_TAG) else []) + tags_in_key + [CONFIG_KEY_AXIS] + env_axes
        params = sorted({k for t in trials for k in t.params} - set(PER_RUN_PARAMS))
        extra = [SWEEP_AXIS, PARENT_AXIS] + [
            PARAM_AXIS_PREFIX + k for k in params if not k.startswith(ENV_CONFIG_PREFIX) and k != ENV_PARAM
        ]
        for axis in extra:
            if separates(axes):
                break
            if varies(axis):
                candidate = [*axes, axis]
                if len({tuple(axis_value(g[0], a) for a in candidate) for g in groups}) > len(
                    {tuple(axis_value(g[0], a) for a in axes) for g in groups}
                ):
                    axes = candidate
        return axes


def axis_value(trial: Trial, axis: str) -> str:
    """A trial's value on one of `Sweep.axes` ("" when it has none)."""
    if axis == CONFIG_KEY_AXIS:
        return trial.config_key
    if axis == SWEEP_AXIS:
        return trial.tags.get(SWEEP_TAG, "")
    if axis == PARENT_AXIS:
        return trial.tags.get(PARENT_TAG, "")[:8]
    if axis.startswith(ENV_CONFIG_PREFIX):
        value = trial.params.get(axis, "")
        # a layout file (the sweep resolves its path): its name says enough
        return Path(value).stem if "/" in value else value
    if axis.startswith(PARAM_AXIS_PREFIX):
        return trial.params.get(axis[len(PARAM_AXIS_PREFIX) :], "")
    return trial.tags.get(axis, "")


def axis_name(axis: str) -> str:
    """How an axis is named in labels and legends: an env-config key by its key ("layout")."""
    for prefix in (ENV_CONFIG_PREFIX, PARAM_AXIS_PREFIX):
        if axis.startswith(prefix):
            return axis[len(prefix) :]
    return axis


def is_env_axis(axis: str) -> bool:
    """The axes that say which environment a configuration ran on (the env id and its config)."""
    return axis == ENV_TAG or axis.startswith(ENV_CONFIG_PREFIX)


def configuration_id(trial: Trial) -> tuple:
    """What makes two runs seeds of one configuration: the same algorithm, config key, env id, env config
    and every other logged param (the settings at their effective values), the seed and per-run params
    (`PER_RUN_PARAMS`) aside."""
    params = tuple(sorted((k, v) for k, v in trial.params.items() if k not in PER_RUN_PARAMS))
    return (trial.tags.get(ALGORITHM_TAG, ""), trial.config_key, trial.env_id, params)


def configurations(trials: list[Trial]) -> dict[tuple, list[Trial]]:
    """The runs grouped by `configuration_id`, in the order of `trials`. A group in which a seed repeats
    holds two runs of one configuration (two sweeps, or one sweep run twice): it is split by the sweep
    (parent) run, so that nothing is counted as a seed twice."""
    groups: dict[tuple, list[Trial]] = {}
    for t in trials:
        groups.setdefault(configuration_id(t), []).append(t)
    out: dict[tuple, list[Trial]] = {}
    for key, group in groups.items():
        seeds = [t.seed for t in group]
        if len(set(seeds)) == len(seeds):
            out[key] = group
            continue
        for t in group:
            out.setdefault((*key, t.tags.get(PARENT_TAG) or t.tags.get(SWEEP_TAG, "")), []).append(t)
    return out


# ---------------------------------------------------------------------------------------------- store


def resolve_tracking_uri(
    arg: str | None, cwd: str | Path = ".", experiment: str | None = None, flag: str = "--tracking-uri"
) -> str:
    """`arg` (given as `flag`), else `$MLFLOW_TRACKING_URI` (a SQLite store's file must exist), else an existing SQLite store that holds the
    experiment: `./mlflow.db` (ARCHITECTURE.md, "Conventions") or `./results/*/mlflow.db` (the sweep spec's default
    `tracking.storage`). Never a fresh empty store: MLflow would create one silently and then report that
    the experiment does not exist, which hides the real mistake (a wrong directory).
    """
    given = arg or os.environ.get("MLFLOW_TRACKING_URI")
    if given:
        where = flag if arg else "MLFLOW_TRACKING_URI"
        if (why := tracking_uri_problem(given)) is not None:
            raise AnalysisError(f"{where} {given!r} is invalid: {why}")
        if (missing := missing_sqlite_file(given)) is not None:
            # MLflow would create an empty store there and then report that the experiment is missing.
            raise AnalysisError(f"{where} {given!r} is invalid: there is no store file {missing}")
        return given
    cwd = Path(cwd).resolve()
    candidates = [cwd / "mlflow.db", *sorted((cwd / "results").glob("*/mlflow.db"))]
    existing = [p for p in candidates if p.is_file()]
    holding = [p for p in existing if experiment is None or experiment in _sqlite_experiment_names(p)]
    if holding:
        return f"sqlite:///{holding[0]}"
    searched = ", ".join(str(p) for p in candidates[:1]) + f", {cwd / 'results'}/*/mlflow.db"
    raise AnalysisError(
        f"no MLflow store given and none found holding experiment {experiment!r} (searched {searched}); "
        "pass --tracking-uri URI or set MLFLOW_TRACKING_URI"
    )


def _sqlite_experiment_names(path: Path) -> set[str]:
    # Read-only peek so that looking for the right store never migrates or creates one.
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            return {row[0] for row in con.execute("SELECT name FROM experiments")}
        finally:
            con.close()
    except sqlite3.Error:
        return set()


def _client(uri: str):
    import mlflow

    os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
    return mlflow.MlflowClient(tracking_uri=uri)


def moved_artifacts(tracking_uri: str, run_id: str, artifact_uri: str) -> Path | None:
    """Where a run's artifacts are when its SQLite store was moved with them: a carried archive
    (`copilot_ray.carry`) unpacked on another machine keeps the store and the artifacts side by side,
    but the store still names the artifacts by the absolute paths of the machine that ran it. Then the
    longest tail of that path (from the run's own folder up) that exists beside the store's file, or one
    folder above it, is where they are. None: the named path exists, the store is not a SQLite file, the
    artifacts are not local files, or no tail from the run's folder on exists there."""
    from urllib.parse import unquote, urlparse

    if not tracking_uri.startswith("sqlite:///"):
        return None
    parsed = urlparse(artifact_uri)
    if parsed.scheme not in ("file", ""):
        return None
    named = Path(unquote(parsed.path))
    if named.exists() or run_id not in named.parts:
        return None
    parts = named.parts[1:] if named.is_absolute() else named.parts
    last = parts.index(run_id)  # a tail must keep the run's own folder
    db = Path(tracking_uri[len("sqlite:///") :]).resolve()
    for base in (db.parent, db.parent.parent):
        for i in range(last + 1):
            candidate = base.joinpath(*parts[i:])
            if candidate.is_dir():
                return candidate
    return None


class RunArtifacts:
    """A run's artifacts: through the tracking store, or from where a moved store's artifacts are
    (`moved_artifacts`); `list` and `download` as MLflow's client has them."""

    def __init__(self, tracking_uri: str, run_id: str, artifact_uri: str | None = None, client=None):
        self.client = client or _client(tracking_uri)
        self.run_id = run_id
        if artifact_uri is None:
            artifact_uri = self.client.get_run(run_id).info.artifact_uri
        self.moved = moved_artifacts(tracking_uri, run_id, artifact_uri or "")

    def list(self, path: str | None = None) -> list:
        if self.moved is not None:
            from mlflow.store.artifact.local_artifact_repo import LocalArtifactRepository

            return LocalArtifactRepository(str(self.moved)).list_artifacts(path)
        return self.client.list_artifacts(self.run_id, path)

    def download(self, path: str, dst: str) -> str:
        if self.moved is not None:
            from mlflow.store.artifact.local_artifact_repo import LocalArtifactRepository

            return LocalArtifactRepository(str(self.moved)).download_artifacts(path, dst)
        return self.client.download_artifacts(self.run_id, path, dst)


def _all_runs(client, experiment_id: str, filter_string: str = "") -> list:
    runs, token = [], None
    while True:
        page = client.search_runs([experiment_id], filter_string, max_results=1000, page_token=token)
        runs.extend(page)
        token = page.token
        if not token:
            return runs


# ---------------------------------------------------------------------------------------------- sweep


def _trial_order(t: Trial):
    """Trials of several sweeps (or stores) in one comparison: by algorithm, configuration, seed."""
    return (t.tags.get(ALGORITHM_TAG, ""), t.config_key, natural_key(t.seed), t.run_id)


def add_trials_from(sweep: Sweep, tracking_uri: str, experiment: str | None = None) -> int:
    """Adds every trial run of the same experiment in another store (runs that ran apart, e.g. two
    sweeps side by side with their own SQLite files), or of `experiment` there (one method rerun in an
    experiment of its own); returns how many. Run ids must not repeat."""
    other = load_sweep(tracking_uri, experiment or sweep.experiment, ALL_SWEEPS, tasks=sweep.tasks)
    known = {t.run_id for t in sweep.trials}
    twice = sorted(known & {t.run_id for t in other.trials})
    if twice:
        raise AnalysisError(
            f"runs {twice[:3]} are in {tracking_uri} and in {sweep.tracking_uri}: give each store once"
        )
    sweep.trials.extend(other.trials)
    sweep.trials.sort(key=_trial_order)
    sweep.sweep_name += " + " + other.sweep_name
    sweep.parents.extend(other.parents)
    if other.experiment != sweep.experiment and other.experiment not in sweep.joined_experiments:
        sweep.joined_experiments.append(other.experiment)
    return len(other.trials)


def load_sweep(
    tracking_uri: str, experiment: str, parent_run_id: str | None = None, tasks: str = TEST
) -> Sweep:
    """All child runs of one sweep with their success curves and wall time.

    With several sweep (parent) runs in the experiment, the newest is used unless `parent_run_id` says
    otherwise (`"all"`: every one of them, e.g. the parts of a several-spec file; the report is logged to
    the newest); the others are reported. Without any parent run, every trial run in the experiment is used.
    `tasks` (TASK_SETS): whose evaluations the trials' copilot/eval/ figures hold (`on_validation_tasks`).
    """
    if tasks not in TASK_SETS:
        raise AnalysisError(f"tasks {tasks!r} is not one of {', '.join(TASK_SETS)}")
    client = _client(tracking_uri)
    exp = client.get_experiment_by_name(experiment)
    if exp is None:
        names = sorted(e.name for e in client.search_experiments(max_results=1000))
        raise AnalysisError(
            f"experiment {experiment!r} not found at {tracking_uri}; experiments there: "
            + (", ".join(repr(n) for n in names) if names else "(none)")
        )
    runs = _all_runs(client, exp.experiment_id)
    parents = sorted(
        (r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_SWEEP),
        key=lambda r: r.info.start_time or 0,
        reverse=True,
    )
    if parent_run_id == ALL_SWEEPS:  # e.g. the parts of a several-spec file: one comparison
        children = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
        if not children:
            raise AnalysisError(f"experiment {experiment!r} has no child (trial) runs at {tracking_uri}")
        tasks = _resolve_tasks(tasks, parents)
        trials = [_trial(client, r, tasks, _budgets(parents)) for r in children]
        trials.sort(key=_trial_order)
        names = sorted({p.data.tags.get(SWEEP_TAG, p.info.run_id) for p in parents})
        return Sweep(
            tasks=tasks,
            tracking_uri=tracking_uri,
            experiment=experiment,
            experiment_id=exp.experiment_id,
            parent_run_id=parents[0].info.run_id if parents else None,
            sweep_name=" + ".join(names) or experiment,
            trials=trials,
            parents=[_parent_entry(tracking_uri, p) for p in parents],
        )
    if parent_run_id is not None:
        chosen = [p for p in parents if p.info.run_id == parent_run_id]
        if not chosen:
            raise AnalysisError(
                f"--parent-run {parent_run_id!r} is not a sweep run of experiment {experiment!r}; sweep runs: "
                + (", ".join(p.info.run_id for p in parents) or "(none)")
            )
        parent = chosen[0]
    else:
        parent = parents[0] if parents else None

    if parent is not None:
        children = [r for r in runs if r.data.tags.get(PARENT_TAG) == parent.info.run_id]
    else:
        children = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    if not children:
        where = f"sweep run {parent.info.run_id}" if parent else f"experiment {experiment!r}"
        raise AnalysisError(f"{where} has no child (trial) runs at {tracking_uri}")

    tasks = _resolve_tasks(tasks, [parent] if parent is not None else [])
    trials = [_trial(client, r, tasks, _budgets([parent] if parent is not None else [])) for r in children]
    trials.sort(key=lambda t: (t.config_key, natural_key(t.seed), t.run_id))
    sweep_name = (parent.data.tags.get(SWEEP_TAG) if parent else None) or (
        children[0].data.tags.get(SWEEP_TAG, experiment)
    )
    return Sweep(
        tracking_uri=tracking_uri,
        experiment=experiment,
        experiment_id=exp.experiment_id,
        parent_run_id=parent.info.run_id if parent else None,
        sweep_name=sweep_name,
        trials=trials,
        other_parent_ids=[
            p.info.run_id for p in parents if parent is None or p.info.run_id != parent.info.run_id
        ],
        parents=[_parent_entry(tracking_uri, parent)] if parent else [],
        tasks=tasks,
    )


def _resolve_tasks(tasks: str, parents: list) -> str:
    if tasks != AUTO:
        return tasks
    searches = bool(parents) and all(p.data.params.get(SEARCHER_PARAM) in SEARCHES for p in parents)
    return VALIDATION if searches else TEST


def _budgets(parents: list) -> dict[str, float]:
    """Sweep (parent) run id -> its env-step budget; sweeps stopped by iterations alone have none."""
    out = {}
    for p in parents:
        try:
            out[p.info.run_id] = float(p.data.params.get(BUDGET_PARAM, "nan"))
        except ValueError:  # "None": stopped by iterations
            pass
    return out


def _parent_entry(tracking_uri: str, run) -> tuple[str, str, str]:
    return tracking_uri, run.info.run_id, run.data.tags.get(SWEEP_TAG, run.info.run_id)


def spec_artifacts(tracking_uri: str, run_id: str) -> list[str]:
    """The spec files a sweep (parent) run holds: `spec.resolved.yaml` (what ran) and `spec.yaml`
    (what was given); [] when there are none or the artifact store cannot be read."""
    try:
        names = {f.path for f in RunArtifacts(tracking_uri, run_id).list()}
    except Exception:  # provenance must not cost the report
        return []
    return [n for n in (RESOLVED_SPEC_ARTIFACT, SPEC_ARTIFACT) if n in names]


def _trial(client, run, tasks: str = TEST, budgets: dict[str, float] | None = None) -> Trial:
    tags = dict(run.data.tags)
    trial = Trial(
        run_id=run.info.run_id,
        run_name=run.info.run_name or run.info.run_id[:8],
        status=run.info.status,
        config_key=tags.get(CONFIG_KEY_TAG, "default"),
        seed=tags.get(SEED_TAG, run.data.params.get(SEED_PARAM, "?")),
        tags=tags,
        tracking_uri=str(client.tracking_uri),
        latest=dict(run.data.metrics),
        params=dict(run.data.params),
        budget=(budgets or {}).get(tags.get(PARENT_TAG, ""), float("nan")),
    )
    prefixes = (*DIAGNOSTIC_PREFIXES, PATHS_PREFIX, *((VALIDATION_PREFIX,) if tasks == VALIDATION else ()))
    # The privilege counts too: success against the checks spent (the privilege-matched comparison), and
    # each count read where the final success is read (`aggregate._count_at`).
    wanted = {*CURVE_METRICS, *PRIVILEGE_COUNTS} | {k for k in run.data.metrics if k.startswith(prefixes)}
    for key in sorted(wanted):
        if key in run.data.metrics:  # the latest value is present iff a history exists: saves a query
            trial.curves[key] = metric_curve(client, run.info.run_id, key)
    trial.curves = fresh_only(trial.curves, trial.curves.get(EVAL_FRESH))  # loaded above: under copilot/eval/
    trial.wall_time_s = float(run.data.metrics.get(TIME_TOTAL_S, float("nan")))
    try:
        artifacts = RunArtifacts(str(client.tracking_uri), run.info.run_id, run.info.artifact_uri, client)
        trial.tree_artifacts = sorted(f.path for f in artifacts.list(TREES_DIR) if f.path.endswith(".npz"))
    except Exception:  # an unreachable artifact store must not cost the whole report its tables
        trial.tree_artifacts = []
    if tasks == VALIDATION:
        on_validation_tasks(trial)
    return trial


def on_validation_tasks(trial: Trial) -> None:
    """Puts the validation tasks' figures where the report reads the test tasks': each copilot/eval/<x>
    (curve and last value) becomes its copilot/validation/<x> twin, or goes where there is none, so that a
    report on validation tasks holds nothing measured on the test tasks; so do the paths' figures
    (paths/*) and the sub-goal tree snapshots, which exist for test tasks only. copilot/eval/fresh (which
    rows evaluated: both sets are evaluated together) stays."""
    for figures in (trial.curves, trial.latest):
        for key in [k for k in figures if k.startswith(PATHS_PREFIX)]:
            del figures[key]
        for key in [k for k in figures if k.startswith(EVAL_PREFIX) and k != EVAL_FRESH]:
            del figures[key]
            if (twin := validation_key(key)) in figures:
                figures[key] = figures[twin]
    trial.tree_artifacts = []


def metric_curve(client, run_id: str, key: str) -> tuple[np.ndarray, np.ndarray]:
    """One metric's history as (steps, values), sorted by step."""
    hist = client.get_metric_history(run_id, key)
    steps = np.array([m.step for m in hist], dtype=np.float64)
    values = np.array([m.value for m in hist], dtype=np.float64)
    order = np.argsort(steps, kind="stable")
    return steps[order], values[order]


def metric_histories(tracking_uri: str, run_id: str, keys) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """`metric_curve` of each of `keys` of one run (one client for all)."""
    client = _client(tracking_uri)
    return {key: metric_curve(client, run_id, key) for key in keys}


def fresh_only(
    curves: dict[str, tuple[np.ndarray, np.ndarray]], fresh: tuple[np.ndarray, np.ndarray] | None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The evaluation curves (copilot/eval/..., copilot/validation/...) at the steps where `fresh`
    (the history of copilot/eval/fresh) is 1: the rows in between repeat the last evaluation and would
    draw flat steps and move "final" and areas. Without `fresh` (`copilot_ray.train` runs, older stores:
    every row is an evaluation) the curves are returned as they are. A curve left empty is dropped."""
    if fresh is None:
        return curves
    fresh_steps = fresh[0][fresh[1] >= 0.5]
    out = {}
    for key, (steps, values) in curves.items():
        if key.startswith(EVALUATION_PREFIXES) and key != EVAL_FRESH:
            keep = np.isin(steps, fresh_steps)
            steps, values = steps[keep], values[keep]
            if not len(steps):
                continue
        out[key] = (steps, values)
    return out


def natural_key(value: str):
    try:
        return (0, float(value), "")
    except (TypeError, ValueError):
        return (1, 0.0, str(value))


# ---------------------------------------------------------------------------------------------- trees


@dataclass
class TreeSnapshot:
    """One `trees_iterNNNNNN.npz`: the deterministic sub-goal trees of the fixed test tasks."""

    iteration: int
    env_steps: int
    depth: int
    trees: np.ndarray  # [n_tasks, 2^K + 1, goal_dim]
    subtask_steps: np.ndarray  # [n_tasks, K + 1, 2^K], -1 beyond 2^k entries
    subtask_reached: np.ndarray  # bool, same shape
    layout: str
    # The planner's obstacles (absent in older snapshots): boxes [n, 2] low / high and the region [2, 2]
    walls_lo: np.ndarray | None = None
    walls_hi: np.ndarray | None = None
    region: np.ndarray | None = None
    # tau_hat profile (absent in older snapshots): mean segment length and mean tau_hat per probe length
    tau_hat_length: np.ndarray | None = None
    tau_hat: np.ndarray | None = None

    def layer_path(self, task: int, k: int) -> np.ndarray:
        """Layer k's path: tree indices j * 2^(K-k), j = 0..2^k."""
        return self.trees[task, :: 2 ** (self.depth - k)]


def load_tree_snapshots(tracking_uri: str, run_id: str, paths: list[str]) -> list[TreeSnapshot]:
    """Download only the named npz artifacts (a long run has one per evaluation) and parse them."""
    artifacts = RunArtifacts(tracking_uri, run_id)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in paths:
            local = artifacts.download(path, tmp)
            with np.load(local, allow_pickle=False) as z:
                out.append(
                    TreeSnapshot(
                        iteration=int(z["iteration"]),
                        env_steps=int(z["env_steps"]),
                        depth=int(z["depth"]),
                        trees=np.asarray(z["trees"], dtype=np.float64),
                        subtask_steps=np.asarray(z["subtask_steps"]),
                        subtask_reached=np.asarray(z["subtask_reached"], dtype=bool),
                        layout=str(z["layout"]) if "layout" in z.files else "",
                        **{k: np.asarray(z[k]) for k in ("walls_lo", "walls_hi", "region") if k in z.files},
                        tau_hat_length=np.asarray(z["tau_hat_length"])
                        if "tau_hat_length" in z.files
                        else None,
                        tau_hat=np.asarray(z["tau_hat"]) if "tau_hat" in z.files else None,
                    )
                )
    return out


def log_report_artifacts(
    tracking_uri: str, parent_run_id: str, out_dir: Path, artifact_path: str = REPORT_ARTIFACT
):
    _client(tracking_uri).log_artifacts(parent_run_id, str(out_dir), artifact_path)
