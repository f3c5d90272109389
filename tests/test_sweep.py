"""`python -m copilot_ray.sweep`: spec checks from the CLI, the smoke sweep tracked in MLflow, resume.

The Ray runs use a cheaper copy of sweeps/smoke.yaml (130 env steps per trial instead of 1500, SAC's
learning starting after them) with its storage in tmp_path: the wiring is what is tested here, not
learning.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest
import yaml

from copilot_ray.keys import (
    ALPHA_SCHEDULE_TAG,
    B_TAG,
    CHECKPOINT_ARTIFACT,
    CONFIG_ARTIFACT,
    CONFIG_KEY_TAG,
    ENV_STEPS,
    GIT_COMMIT_TAG,
    K_TAG,
    PARENT_TAG,
    PRIVILEGE_COLLISION_CHECKS,
    PRIVILEGES_TAG,
    ROLE_SWEEP,
    ROLE_TAG,
    ROLE_TRIAL,
    SEED_TAG,
    SPEC_ARTIFACT,
    SUCCESS_PLANNED,
    SUMMARY_ARTIFACT,
    SWEEP_TAG,
    TRAINING_ITERATION,
    TREES_DIR,
    TRIAL_ID_TAG,
)

ROOT = Path(__file__).resolve().parent.parent
SWEEPS = sorted((ROOT / "sweeps").glob("*.yaml"))


def _smoke_copy(tmp_path: Path, env_steps: int = 130) -> Path:
    data = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    data["tracking"] = {"storage": str(tmp_path / "results")}
    data["stop"] = {"env_steps": env_steps, "min_evaluations": 1}  # a smoke run: it only has to run
    # and not learn: SAC's updates, not its env steps, are what a longer smoke trial would spend its time on
    data["config"]["num_steps_sampled_before_learning_starts"] = max(256, env_steps + 1)
    path = tmp_path / "smoke.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _runs(spec):
    import mlflow

    client = mlflow.MlflowClient(spec.tracking.uri)
    exp = client.get_experiment_by_name(spec.experiment)
    runs = client.search_runs([exp.experiment_id], max_results=1000)
    parents = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_SWEEP]
    children = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    return client, parents, children


# ------------------------------------------------------------------------------------- no Ray at all
def test_cli_bad_spec_exits_2_naming_the_key_without_ray(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "name: bad\nenv: {id: maze-point, config: {layout: u-maze}}\n"
        "search: {tree_depth: {grid: [1, 99]}}\nstop: {env_steps: 100, min_evaluations: 1}\n"
    )
    wrapper = (
        "import runpy, sys\n"
        f"sys.argv = ['copilot_ray.sweep', {str(bad)!r}]\n"
        "try:\n    runpy.run_module('copilot_ray.sweep', run_name='__main__')\n"
        "except SystemExit as e:\n    code = e.code\n"
        "print('RAY_IMPORTED', 'ray' in sys.modules)\n"
        "sys.exit(code)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-c", wrapper], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2, proc.stderr
    assert "search.tree_depth.grid[1]" in proc.stderr and "99" in proc.stderr
    assert "RAY_IMPORTED False" in proc.stdout


def _storage_run(spec: Path, *args: str) -> subprocess.CompletedProcess:
    """`python -m copilot_ray.sweep SPEC ARGS`, reporting whether Ray was imported."""
    wrapper = (
        "import runpy, sys\n"
        f"sys.argv = ['copilot_ray.sweep', {str(spec)!r}, *{list(args)!r}]\n"
        "try:\n    runpy.run_module('copilot_ray.sweep', run_name='__main__')\n"
        "except SystemExit as e:\n    code = e.code\n"
        "print('RAY_IMPORTED', 'ray' in sys.modules)\n"
        "sys.exit(code)\n"
    )
    return subprocess.run(
        [sys.executable, "-c", wrapper], cwd=ROOT, capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize("check", [True, False], ids=["--check", "run"])
@pytest.mark.parametrize("key", ["storage", "uri"])
def test_a_storage_or_store_that_cannot_be_written_is_refused_before_ray(tmp_path, key, check):
    """A file where the results' folder must go: one line naming the key and value, exit 2, no Ray,
    nothing created, whether asked for the plan or the run."""
    blocker = tmp_path / "a_file"
    blocker.write_text("in the way")
    data = yaml.safe_load(_smoke_copy(tmp_path).read_text())
    bad = str(blocker / "results") if key == "storage" else f"sqlite:///{blocker}/mlflow.db"
    data["tracking"][key] = bad
    spec = tmp_path / "unwritable.yaml"
    spec.write_text(yaml.safe_dump(data))
    proc = _storage_run(spec, *(["--check"] if check else []))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert f"tracking.{key}: {bad!r} is invalid: {blocker} is a file" in proc.stderr
    assert "RAY_IMPORTED False" in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "smoke.yaml", "unwritable.yaml"]


@pytest.mark.parametrize("check", [True, False], ids=["--check", "run"])
def test_a_tracking_uri_flag_that_cannot_be_written_is_refused(tmp_path, check):
    blocker = tmp_path / "a_file"
    blocker.write_text("in the way")
    uri = f"sqlite:///{blocker}/sub/mlflow.db"
    proc = _storage_run(_smoke_copy(tmp_path), "--check", "--tracking-uri", uri)
    assert proc.returncode == 2 and f"--tracking-uri {uri!r} is invalid: {blocker} is a file" in proc.stderr
    # a folder nothing can be made in, though os.access says root may write there (found by a reviewer:
    # --check passed, the run died in MLflow after Ray had started)
    uri = "sqlite:////proc/nope/mlflow.db"
    proc = _storage_run(_smoke_copy(tmp_path), *(["--check"] if check else []), "--tracking-uri", uri)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.splitlines() == [
        f"--tracking-uri {uri!r} is invalid: nothing can be made in /proc (No such file or directory), "
        "so /proc/nope/mlflow.db cannot be made"
    ]
    assert "RAY_IMPORTED False" in proc.stdout and "starting Ray" not in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "smoke.yaml"]


@pytest.mark.parametrize(
    ("address", "why"),
    [
        ("127.0.0.1:1", "nothing answers at 127.0.0.1:1 ("),
        ("ray://127.0.0.1:1", "nothing answers at 127.0.0.1:1 ("),
        ("nope.invalid:6379", "nope.invalid is not a known host"),
        ("nope", "must be auto, HOST:PORT or ray://HOST:PORT"),
    ],
)
@pytest.mark.parametrize("check", [True, False], ids=["--check", "run"])
def test_an_address_where_no_cluster_answers_is_refused_before_ray(tmp_path, address, why, check):
    """A mistyped --address: Ray's own connect waited for its cluster for over ten minutes (--check
    too); now one line naming the flag and value, exit 2 within seconds, no Ray, nothing written."""
    proc = _storage_run(_smoke_copy(tmp_path), *(["--check"] if check else []), "--address", address)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    (line,) = proc.stderr.splitlines()
    assert line.startswith(f"--address {address!r} is invalid: {why}"), line
    assert "RAY_IMPORTED False" in proc.stdout and "starting Ray" not in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["smoke.yaml"]


@pytest.mark.parametrize("path", SWEEPS, ids=[p.stem for p in SWEEPS])
def test_check_prints_the_plan_of_every_shipped_spec(path, capsys):
    from copilot_ray.sweep import main
    from copilot_ray.sweep_spec import load_specs

    assert main([str(path), "--check"]) == 0
    out = capsys.readouterr().out
    for spec in load_specs(path):  # every part's plan
        assert f"sweep {spec.name!r}" in out and f"{len(spec.trial_plan())} trial(s)" in out


@pytest.mark.parametrize("ran", [False, True], ids=["--resume, never ran", "ran, no --resume"])
def test_a_start_that_does_not_match_the_results_is_refused_before_ray_and_writes_nothing(tmp_path, ran):
    """--resume of a sweep that never ran, and a second start of one that ran without --resume: one
    error line, exit 2, and neither Ray's start announced nor its console log (or anything) written."""
    spec = _smoke_copy(tmp_path)
    tune = tmp_path / "results" / "smoke" / "tune" / "smoke"
    if ran:
        tune.mkdir(parents=True)
    proc = _storage_run(spec, *([] if ran else ["--resume"]))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    expected = "already holds this sweep's results: add --resume" if ran else "error: nothing to resume"
    assert len(proc.stderr.splitlines()) == 1 and expected in proc.stderr, proc.stderr
    assert "starting Ray" not in proc.stdout and "RAY_IMPORTED False" in proc.stdout
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert written == (["results", "results/smoke", "results/smoke/tune", str(tune.relative_to(tmp_path))]
                       if ran else []) + ["smoke.yaml"]  # fmt: skip


def test_resume_of_a_file_of_parts_none_of_which_ran_is_refused(tmp_path, capsys):
    """No part's Tune folder and no store to resume from: refused, nothing written."""
    from copilot_ray.sweep import main

    data = yaml.safe_load(_smoke_copy(tmp_path).read_text())
    path = tmp_path / "parts.yaml"
    path.write_text(yaml.safe_dump_all([{**data, "name": "one"}, {**data, "name": "two"}], sort_keys=False))
    assert main([str(path), "--resume"]) == 2
    assert capsys.readouterr().err.startswith(f"error: nothing to resume: no part of {path} has run here")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["parts.yaml", "smoke.yaml"]


def test_existing_results_need_resume(tmp_path):
    from copilot_ray.sweep import SweepError, run_sweep
    from copilot_ray.sweep_spec import load_spec

    spec = load_spec(_smoke_copy(tmp_path))
    (Path(spec.tracking.storage) / spec.name / "tune" / spec.name).mkdir(parents=True)
    with pytest.raises(SweepError, match="--resume"):
        run_sweep(spec)


# ------------------------------------------------------------------------------------- on Ray
def _assert_tracked_once(spec) -> None:
    """The smoke sweep's two trials in MLflow: one FINISHED parent with the outcome per configuration,
    one FINISHED child per trial with its tags, privileges, metrics against env steps and artifacts."""
    client, parents, children = _runs(spec)
    assert len(parents) == 1 and len(children) == 2
    parent = parents[0]
    assert parent.data.tags[SWEEP_TAG] == "smoke" and parent.info.status == "FINISHED"
    assert {a.path for a in client.list_artifacts(parent.info.run_id)} >= {SPEC_ARTIFACT, SUMMARY_ARTIFACT}
    # the parent row carries the outcome per configuration (validation figures), and the best of them
    summary = parent.data.metrics
    assert {"summary/tree_depth_1/validation_success", "summary/tree_depth_2/validation_success"} <= set(
        summary
    )
    assert summary["summary/best/validation_success"] == max(
        summary["summary/tree_depth_1/validation_success"], summary["summary/tree_depth_2/validation_success"]
    )
    # the experiment opens on its runs in MLflow's UI
    exp = client.get_experiment(parent.info.experiment_id)
    assert exp.tags["mlflow.experimentKind"] == "custom_model_development"
    by_depth = {}
    for run in children:
        tags, params = run.data.tags, run.data.params
        assert tags[PARENT_TAG] == parent.info.run_id
        assert tags[SWEEP_TAG] == "smoke" and tags[SEED_TAG] == "0" and tags[B_TAG] == "1"
        assert tags[K_TAG] == params["tree_depth"] and tags[CONFIG_KEY_TAG] == f"tree_depth={tags[K_TAG]}"
        assert tags[GIT_COMMIT_TAG] and tags[ALPHA_SCHEDULE_TAG] == "paper_per_task"
        # CO-PILOT's planner pays its collision penalty with ground-truth checks: declared and counted
        assert "collision_checks" in tags[PRIVILEGES_TAG].split(",")
        checks = client.get_metric_history(run.info.run_id, PRIVILEGE_COLLISION_CHECKS)
        assert checks and checks[-1].value > 0
        assert run.info.status == "FINISHED"
        success = client.get_metric_history(run.info.run_id, SUCCESS_PLANNED)
        steps = client.get_metric_history(run.info.run_id, ENV_STEPS)
        assert success and [m.step for m in success] == [int(m.value) for m in steps]
        got = [m.step for m in success]
        assert got == sorted(set(got))  # strictly increasing env steps
        assert success[-1].step >= 130
        arts = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert {CONFIG_ARTIFACT, CHECKPOINT_ARTIFACT, TREES_DIR} <= arts
        assert client.list_artifacts(run.info.run_id, CHECKPOINT_ARTIFACT)
        by_depth[params["tree_depth"]] = run
    assert set(by_depth) == {"1", "2"}


def _checkpoint_of(name: str) -> tuple[str, str] | None:
    """(trial folder, checkpoint folder) of a path inside a trial's checkpoint, else None."""
    parts = Path(name).parts
    at = next((i for i, part in enumerate(parts) if part.startswith("checkpoint_")), None)
    return None if at is None else (parts[at - 1], parts[at])


def _checkpoints_tune_restores(tune_folder: Path) -> set[tuple[str, str]]:
    """The checkpoint Tune resumes each trial under ``tune_folder`` from, read with Ray's own decoder
    (the latest registered in its newest experiment state; it can lag the newest checkpoint folder)."""
    from ray.tune.execution.experiment_state import _find_newest_experiment_checkpoint
    from ray.tune.utils.serialization import TuneFunctionDecoder

    (experiment,) = tune_folder.iterdir()
    state = json.loads(Path(_find_newest_experiment_checkpoint(str(experiment))).read_text())
    restored = set()
    for _, run_metadata in state["trial_data"]:
        manager = json.loads(run_metadata, cls=TuneFunctionDecoder, allow_cloudpickle=True)[
            "checkpoint_manager"
        ]
        if manager.latest_checkpoint_result:
            path = Path(manager.latest_checkpoint_result.checkpoint.path)
            restored.add((path.parent.name, path.name))
    return restored


class _TuneRecords(logging.Handler):
    """The messages Tune's loggers emit in the driver while it is attached, by level, formatted as Ray's
    console handler writes them (ray/_private/log.py; the test session's Ray leaves Ray's logging alone)."""

    def __init__(self) -> None:
        super().__init__()
        self.setFormatter(
            logging.Formatter("%(asctime)s\t%(levelname)s %(filename)s:%(lineno)s -- %(message)s")
        )

    def __enter__(self):
        self.records: list[tuple[int, str]] = []
        logging.getLogger("ray.tune").addHandler(self)
        return self

    def __exit__(self, *exc):
        logging.getLogger("ray.tune").removeHandler(self)

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append((record.levelno, self.format(record)))


def test_a_sweep_cut_mid_trial_is_carried_and_resumed_each_trial_tracked_once(
    ray_session, tmp_path, monkeypatch, capsys
):
    """The smoke sweep, Ctrl-C'd at its second trial's 2nd result, packed by `copilot_ray.carry`, its
    results deleted and the archive unpacked in their place (a new machine), then resumed: the archive
    holds the files of the one checkpoint Tune restores the cut trial from (its other checkpoints as
    empty folders, none of the finished trial's); both trials are then tracked once, completely, each
    iteration logged once, and the Ray the test started is left running. The cut prints one way to
    resume, naming the spec file as given (Tune's own hint is a notice for the console log), and the
    resume's Tune INFO lines are all notices."""
    from copilot_ray import carry
    from copilot_ray.commands import python_module
    from copilot_ray.console import is_notice
    from copilot_ray.sweep import run_sweep, sweep_root
    from copilot_ray.sweep_spec import load_spec
    from tests import interrupts, stores

    path = _smoke_copy(tmp_path, env_steps=360)
    data = yaml.safe_load(path.read_text())
    data["search"]["tree_depth"]["grid"] = [2, 1]  # K = 1 second: 3 iterations of 120 env steps (K = 2: 2)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    monkeypatch.chdir(tmp_path)
    spec = load_spec(path.name)  # as typed: relative to the folder it runs in
    with _TuneRecords() as tune_said:
        first = run_sweep(spec, extra_callbacks=[interrupts.at_result_after_a_finished_trial(2)])
    assert first.status == "interrupted" and first.exit_code == 130
    printed = capsys.readouterr().out
    assert printed.count("Resume with") == 1
    assert f"Resume with: {python_module('copilot_ray.sweep', 'smoke.yaml', '--resume')}\n" in printed
    hints = [m for _, m in tune_said.records if "Tuner.restore" in m]
    assert hints and all(is_notice(m) for m in hints)
    assert [r.status for r in first.rows] == ["finished", "unfinished"]
    _, parents, children = _runs(spec)
    assert len(parents) == 1 and parents[0].info.status == "KILLED"
    assert sorted(c.info.status for c in children) == ["FINISHED", "KILLED"]

    out = tmp_path / "carried.tar.gz"
    # with the final checkpoints: the finished run's is one of the artifacts checked after the resume
    (state,) = carry.pack(path, out, tmp_path, final_checkpoints=True)
    assert not state.finished and state.has_tune
    with tarfile.open(out) as archive:
        members = archive.getmembers()
    with_files = {_checkpoint_of(m.name) for m in members if m.isfile()} - {None}
    empty = {_checkpoint_of(m.name) for m in members if m.isdir()} - {None} - with_files
    assert len(with_files) == 1 and empty  # one checkpoint keeps its files, the cut trial's others none
    restored = _checkpoints_tune_restores(sweep_root(spec) / "tune")
    assert with_files < restored  # the cut trial's; the finished trial's is not packed

    shutil.rmtree(tmp_path / "results")  # a new machine: only the archive is left
    stores.forget_open_stores(str(tmp_path))
    with tarfile.open(out) as archive:
        archive.extractall(tmp_path, filter="data")
    with _TuneRecords() as tune_said:
        second = run_sweep(load_spec(path), resume=True)
    assert [m for level, m in tune_said.records if level == logging.INFO and not is_notice(m)] == []
    assert second.status == "finished" and second.exit_code == 0, second.summary
    assert second.parent_run_id == first.parent_run_id
    assert ray_session.is_initialized()  # a Ray it did not start is left running
    assert sorted(r.config_key for r in second.rows) == ["tree_depth=1", "tree_depth=2"]
    _assert_tracked_once(spec)
    client, parents, children = _runs(spec)
    assert len({c.data.tags[TRIAL_ID_TAG] for c in children}) == 2
    for run in children:
        assert run.info.status == "FINISHED"
        history = sorted(client.get_metric_history(run.info.run_id, TRAINING_ITERATION), key=lambda m: m.step)
        iterations = [int(m.value) for m in history]
        assert iterations == list(range(1, len(iterations) + 1)) and len(iterations) >= 2  # to the end, once
        assert len({m.step for m in history}) == len(history)


def test_a_file_of_several_specs_runs_each_part_into_one_experiment(
    ray_session, tmp_path, monkeypatch, capsys
):
    """RRT* then SGT-PG on two agents (env.id as a list), one MLflow experiment; the second part divides
    by the reference the first one stored."""
    from copilot_ray.keys import ALGORITHM_TAG, ENV_TAG, PATH_LENGTH_VS_RRT, PATH_SUCCESS
    from copilot_ray.sweep import main
    from copilot_ray.sweep_spec import load_specs

    common = {
        "experiment": "planners",
        "env": {"id": ["maze-point", "maze-rigid"], "config": {"layout": "u-maze"}},
        "seeds": [0],
        "resources": {"max_concurrent_trials": 2, "num_env_runners": 0},
        "tracking": {"storage": str(tmp_path / "results"), "uri": f"sqlite:///{tmp_path}/planners.db"},
    }
    parts = [
        {
            "name": "p_rrt",
            "algorithm": "rrt_star",
            # 1 s per task: at 0.2 s a busy machine leaves the rigid body's RRT* unsolved tasks (OMPL's
            # limit is wall time), and the SGT-PG part may then share no solved task to divide by
            "config": {"time_limit_s": 1.0, "eval_num_tasks": 4, "tasks_per_iteration": 2},
            "stop": {"iterations": 5},
            **common,
        },
        {
            "name": "p_sgt",
            "algorithm": "sgt_pg",
            "config": {
                "tree_depth": 2,
                "phases_per_iteration": 2,
                "eval_num_tasks": 4,
                "task_batch_size": 4,
                "planner.num_samples": 4,
                "rrt_reference_time_s": 1.0,
            },
            "stop": {"iterations": 2},
            **common,
        },
    ]
    path = tmp_path / "planners.yaml"
    path.write_text("---\n".join(yaml.safe_dump(p, sort_keys=False) for p in parts))
    assert main([str(path)]) == 0
    out = capsys.readouterr().out
    assert out.index("part 1 of 2: p_rrt") < out.index("part 2 of 2: p_sgt")
    # Quiet: the first line says where the notices went; the closing commands run as printed (the
    # report's with an --out of the test's own, the UI's asked for its help: it serves in
    # tests/test_printed_commands.py).
    lines = out.splitlines()
    assert (
        lines[0].startswith(f"sweep {path}: starting Ray")
        and (tmp_path / "results" / "p_rrt" / "console.log").is_file()
    )
    assert any(
        line.startswith("path success, length / RRT*: the planner's paths on the test tasks")
        for line in lines
    )
    report = [line.removeprefix("Report: ") for line in lines if line.startswith("Report: ")][-1]
    done = subprocess.run(
        ["bash", "-c", f"{report} --out {tmp_path / 'report'}"], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "report" / "report.md").is_file()
    ui = [line.removeprefix("MLflow UI: ") for line in lines if line.startswith("MLflow UI: ")][-1]
    assert subprocess.run(["bash", "-c", f"{ui} --help"], capture_output=True, timeout=120).returncode == 0
    # One RRT* reference per agent, stored by the RRT* part and divided by in the SGT-PG part.
    # (the test session's cache, set in conftest.py before Ray started: trial workers see it too)
    cache = Path(os.environ["COPILOT_RAY_CACHE"]) / "rrt_reference"
    assert len(list(cache.glob("maze-*-4tasks-1s-seed0-*.npz"))) == 2

    client, parents, children = _runs(load_specs(path)[0])
    assert sorted(p.data.tags[SWEEP_TAG] for p in parents) == ["p_rrt", "p_sgt"]
    runs = {(r.data.tags[ALGORITHM_TAG], r.data.tags[ENV_TAG]): r for r in children}
    assert set(runs) == {(a, e) for a in ("rrt_star", "sgt_pg") for e in ("maze-point", "maze-rigid")}
    for run in runs.values():
        assert run.info.status == "FINISHED" and run.data.params["env.id"] == run.data.tags[ENV_TAG]
        success = client.get_metric_history(run.info.run_id, PATH_SUCCESS)
        ratio = client.get_metric_history(run.info.run_id, PATH_LENGTH_VS_RRT)
        assert len(success) == 2 and ratio  # RRT*: 2 chunks of 2 tasks; SGT-PG: 2 iterations
        assert [m.step for m in success] == sorted({m.step for m in success})  # steps = checks, growing
    # Nothing is run twice: without --resume a file whose parts have results is refused.
    assert main([str(path)]) == 2
    assert "part 'p_rrt'" in capsys.readouterr().err


def test_summary_shows_the_columns_that_were_logged_and_no_stale_path_figure():
    from copilot_ray.keys import PATH_LENGTH_VS_RRT, PATH_SUCCESS, SUCCESS_DIRECT
    from copilot_ray.sweep_summary import TrialRow, summary_metrics, summary_table

    nan = float("nan")

    def row(key, seed, success, ratio):
        figures = {
            SUCCESS_PLANNED: nan,
            SUCCESS_DIRECT: nan,
            PATH_SUCCESS: success,
            PATH_LENGTH_VS_RRT: ratio,
        }
        return TrialRow(f"t{seed}", key, seed, "finished", figures, 1000, 10.0)

    table = summary_table([row("env.id=maze-point", 0, 0.7, 3.0), row("env.id=maze-point", 1, 0.9, 2.0),
                           row("env.id=maze-rigid", 0, 0.0, nan)])  # fmt: skip
    header, _, point, rigid = table.splitlines()
    assert "path success" in header and "length / RRT*" in header and "planned" not in header
    assert "0.80 [0.70, 0.90]" in point and "2.50 [2.00, 3.00]" in point  # 2 seeds: the range
    five = summary_table([row("env.id=maze-point", s, 0.5 + 0.1 * s, 2.0) for s in range(5)])
    assert "0.70 ± 0.16" in five.splitlines()[2]  # 5 seeds: ± the sample std
    assert rigid.split("|")[4].strip() == "-"  # no successful path at the end: no length ratio
    # A search (Optuna) chooses by validation figures: its summary shows no test-task (paths) figure.
    searched = summary_table([row("env.id=maze-point", 0, 0.7, 3.0)], searched=True)
    assert "path success" not in searched and "length / RRT*" not in searched
    assert not any(
        k.startswith("summary/") and "path" in k for k in summary_metrics([row("a", 0, 0.7, 3.0)], True)
    )
    assert "summary/best/path_success" in summary_metrics([row("a", 0, 0.7, 3.0)])


def test_the_summary_says_which_tasks_each_column_reads():
    """The sweep's table shows the validation tasks' success while the report beside it shows the test
    tasks': the note under the table (and in the parent run) says so, and that a planner's path figures
    are the test tasks'; a search's report reads the validation tasks too."""
    from copilot_ray.keys import EVAL_SUCCESS, PATH_SUCCESS, validation_key
    from copilot_ray.sweep_summary import TrialRow, summary_note

    agent = [TrialRow("t0", "k", 0, "finished", {validation_key(EVAL_SUCCESS): 0.4}, 1000, 10.0)]
    note = summary_note(agent)
    assert note.startswith("validation success: each trial's last evaluation on the VALIDATION tasks")
    assert "the report reads the test tasks' instead" in note and "planner's paths" not in note
    assert "a report of searches alone reads these too" in summary_note(agent, searched=True)
    planner = [TrialRow("t0", "k", 0, "finished", {PATH_SUCCESS: 0.5}, 1000, 10.0)]
    note = summary_note(planner)
    assert note.startswith("path success: the planner's paths on the test tasks") and "VALIDATION" not in note


def test_check_prints_the_store_the_run_would_use(tmp_path, capsys):
    """--check reads --tracking-uri as the run would: its plan names that store, not the spec's."""
    from copilot_ray.sweep import main

    uri = f"sqlite:///{tmp_path / 'elsewhere.db'}"
    assert main([str(ROOT / "sweeps" / "smoke.yaml"), "--check", "--tracking-uri", uri]) == 0
    out = capsys.readouterr().out
    assert uri in out and "results/smoke" not in out.split("MLflow experiment", 1)[1].splitlines()[0]
    assert not (tmp_path / "elsewhere.db").exists()  # a plan opens no store


def test_resume_from_a_carried_store_skips_finished_parts_and_restarts_the_others(
    tmp_path, monkeypatch, capsys
):
    """A comparison file's store copied alone to a new machine (no Tune folders): --resume skips the
    part the store records finished and starts the unfinished one over, its earlier runs discarded so
    that reports and best_of count each trial once."""
    from types import SimpleNamespace

    from copilot_ray import sweep, tracking
    from copilot_ray.sweep_spec import load_specs

    uri = f"sqlite:///{tmp_path}/carried.db"
    base = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    base["tracking"] = {"storage": str(tmp_path / "results"), "uri": uri}
    parts = [{**base, "name": "part_done"}, {**base, "name": "part_cut"}]
    path = tmp_path / "two.yaml"
    path.write_text("---\n".join(yaml.safe_dump(p, sort_keys=False) for p in parts))
    done, cut = load_specs(path)

    _, parent, _ = tracking.open_sweep_run(uri, done.experiment, done.name, resume=False)
    tracking.end_sweep_run(uri, parent, "FINISHED")
    _, cut_parent, _ = tracking.open_sweep_run(uri, cut.experiment, cut.name, resume=False)
    client = tracking._client(uri)
    exp_id = client.get_experiment_by_name(cut.experiment).experiment_id
    client.create_run(exp_id, tags={SWEEP_TAG: cut.name, ROLE_TAG: ROLE_TRIAL, PARENT_TAG: cut_parent})

    studies = Path(cut.tracking.storage) / cut.name / "optuna.db"  # the cut attempt's Optuna studies
    studies.parent.mkdir(parents=True)
    studies.write_bytes(b"old trials")
    ran = []
    monkeypatch.setattr(sweep, "_import_runtime", lambda: SimpleNamespace(start_ray=lambda a: False))
    monkeypatch.setattr(sweep, "_run_one", lambda spec, args, resume: ran.append((spec.name, resume)) or 0)
    assert sweep.main([str(path), "--resume"]) == 0
    assert ran == [("part_cut", False)]
    out = capsys.readouterr().out
    assert "part_done: finished in" in out and "discarded 2 run(s)" in out
    assert tracking.sweep_runs_in_store(uri, cut.experiment, cut.name) == (None, [])
    assert not studies.exists() and len(list(studies.parent.glob("optuna.discarded-*.db"))) == 1
    finished, kept = tracking.sweep_runs_in_store(uri, done.experiment, done.name)
    assert finished == parent and kept == [parent]
    # Without --resume nothing is skipped or discarded.
    ran.clear()
    assert sweep.main([str(path)]) == 0 and ran == [("part_done", False), ("part_cut", False)]


def test_a_sweep_without_address_starts_its_own_ray_whatever_ray_address_says():
    """Without --address a sweep runs on a Ray of its own: a RAY_ADDRESS left in the shell (or a `ray
    start` cluster on this machine) would otherwise capture it, and Ray then refuses its num_cpus. Its
    worker processes wait passively (OpenMP), though the shell set no policy."""
    code = (
        "import os, ray\n"
        "from copilot_ray import tune_runtime\n"
        "assert tune_runtime.start_ray(None)\n"
        "policy = ray.get(ray.remote(lambda: os.environ.get('OMP_WAIT_POLICY')).remote())\n"
        "print(policy, int(ray.cluster_resources()['CPU']))\n"
        "ray.shutdown()\n"
    )
    env = {**os.environ, "RAY_ADDRESS": "127.0.0.1:9", "RAY_AUTH_MODE": "disabled"}
    env.pop("OMP_WAIT_POLICY", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    policy, cpus = out.stdout.split()[-2:]
    assert policy == "PASSIVE" and int(cpus) == os.cpu_count()


def test_closing_a_finished_part_again_keeps_one_entry_per_summary_figure(tmp_path):
    """--resume walks through finished parts and closes each once more: an unchanged summary figure is
    not logged twice (its history keeps one entry); a changed one is, and the latest value is the new."""
    from copilot_ray import tracking

    uri = f"sqlite:///{tmp_path}/store.db"
    _, parent, _ = tracking.open_sweep_run(uri, "exp", "part", resume=False)
    figures = {"summary/best/validation_success": 0.5, "summary/a/validation_success": 0.25}
    tracking.end_sweep_run(uri, parent, "FINISHED", "# table", figures)
    tracking.end_sweep_run(uri, parent, "FINISHED", "# table", figures)
    client = tracking._client(uri)
    for key in figures:
        assert len(client.get_metric_history(parent, key)) == 1
    tracking.end_sweep_run(
        uri, parent, "FINISHED", "# table", {**figures, "summary/a/validation_success": 0.75}, step=900
    )
    history = client.get_metric_history(parent, "summary/a/validation_success")
    assert [m.value for m in history] == [0.25, 0.75]
    assert [m.step for m in history] == [0, 900]  # each stop's summary at its env steps, not twice at one
    assert client.get_run(parent).data.metrics["summary/a/validation_success"] == 0.75
    assert len(client.get_metric_history(parent, "summary/best/validation_success")) == 1
