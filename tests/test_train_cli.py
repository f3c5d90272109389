"""`python -m copilot_ray.train`: flags generated from the settings, presets and bad input, without Ray."""

import subprocess
import sys
from pathlib import Path

import pytest

from copilot_ray import train
from copilot_ray.algorithms.copilot.settings import SETTINGS

ROOT = Path(__file__).resolve().parents[1]


def test_preset_flag_sets_the_readings_and_explicit_flags_override_it():
    config = train.build_config(train.parse_args(["--preset", "paper_literal", "--tau-max", "40"]))
    assert config.preset == "paper_literal" and config.after_failure == "continue"
    assert config.tau_max == 40 and config.subtask_reward == "halving"
    default = train.build_config(train.parse_args([]))
    assert default.preset is None and default.subtask_reward == "uniform" and default.tau_max == 25


def test_a_run_uses_one_torch_thread_and_passive_openmp_threads():
    """Two OpenMP threads on two cores that anything else uses run 10-70x slower than one (measured,
    docs/measured.md): the main process gets one torch thread whatever the core count, and importing the
    package (before torch loads) sets a passive waiting policy that Ray's workers inherit."""
    _, run = train.checked_run(train.parse_args(["--num-env-runners", "0"]))
    assert run.num_cpus_for_main_process == 1
    code = "import os, copilot_ray, torch; print(os.environ['OMP_WAIT_POLICY'])"
    env = {k: v for k, v in __import__("os").environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["PASSIVE"]
    kept = subprocess.run(
        [sys.executable, "-c", code],
        env={**env, "OMP_WAIT_POLICY": "ACTIVE"},
        capture_output=True,
        text=True,
        check=True,
    )
    assert kept.stdout.split() == ["ACTIVE"]  # a policy the user chose is kept


def test_every_setting_but_the_schedule_fields_is_a_flag_with_its_rule_in_the_help():
    parser_help = subprocess.run(
        [sys.executable, "-m", "copilot_ray.train", "--help"], capture_output=True, text=True, check=True
    ).stdout
    flags = [s.flag for s in SETTINGS.values() if s.on_cli]
    assert len(flags) > 40 and "--planner-std-final" in flags and "--initial-alpha" in flags
    for s in SETTINGS.values():
        if s.on_cli:
            assert s.flag in parser_help, s.flag
    assert "--alpha-schedule-kind" not in parser_help  # schedule fields are for sweep specs


def test_flag_values_are_read_as_in_a_spec_and_reach_the_config():
    args = train.parse_args(
        [
            "--planner-std-final",
            "null",
            "--planner-hidden",
            "[8, 8]",
            "--actor-lr",
            "1e-3",
            "--fast-learner",
            "false",
            "--eval-tasks",
            "7",  # the old name of --eval-num-tasks still works
            "--after-failure",
            "abort_layer",
        ]
    )
    config = train.build_config(args)
    assert config.planner["std_final"] is None and config.planner["hidden"] == [8, 8]
    assert config.actor_lr == 1e-3 and config.fast_learner is False
    assert config.eval_num_tasks == 7 and config.after_failure == "abort_layer"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--preset", "paper"], "--preset 'paper' is invalid: must be one of"),
        (["--planner-clip", "1.5"], "--planner-clip 1.5 is invalid: must be a number in (0, 1)"),
        (["--tree-depth", "11"], "--tree-depth 11 is invalid: must be an integer in [1, 10]"),
        (
            ["--collision-cost", "area"],
            "--collision-cost 'area' is invalid: must be one of ['indicator', 'length']",
        ),
        (
            ["--updates-per-env-step", "0.5", "--training-intensity", "64"],
            "both set the update-to-data ratio",
        ),
    ],
)
def test_bad_values_exit_2_naming_flag_and_value(argv, message, capsys):
    assert train.main([*argv, "--stop-iters", "1"]) == 2
    assert message in capsys.readouterr().err


# Found by a new user: -5 steps trained, ftp:// failed after Ray started, a YAML typo dumped a traceback.
NEWCOMERS_BAD_FLAGS = [
    (["--planner-clip", "1.5"], "--planner-clip 1.5 is invalid"),
    (["--stop-env-steps", "-5"], "--stop-env-steps -5 is invalid: must be an integer >= 1"),
    (["--tracking-uri", "ftp://x"], "--tracking-uri 'ftp://x' is invalid: ftp:// is not a store"),
    (["--planner-hidden", "[64,64"], "--planner-hidden: '[64,64' is invalid: not a value"),
    (["--layout", "nope"], "--layout 'nope' is invalid"),
    (["--env", "maze-pont"], "--env 'maze-pont' is invalid: unknown env id"),
    # a store or checkpoint folder under a file: refused before Ray, not a FileNotFoundError after it
    (
        ["--tracking-uri", f"sqlite:///{ROOT}/pyproject.toml/mlflow.db"],
        f"--tracking-uri 'sqlite:///{ROOT}/pyproject.toml/mlflow.db' is invalid: {ROOT}/pyproject.toml is a file",
    ),
    # a folder nothing can be made in, though os.access lets root write there: Ray started, then failed
    (
        ["--tracking-uri", "sqlite:////proc/nope/mlflow.db"],
        "--tracking-uri 'sqlite:////proc/nope/mlflow.db' is invalid: nothing can be made in /proc",
    ),
    (
        ["--checkpoint-dir", "/proc/nope/run"],
        "--checkpoint-dir '/proc/nope/run' is invalid: nothing can be made in /proc",
    ),
    (
        ["--checkpoint-dir", f"{ROOT}/pyproject.toml/run"],
        f"--checkpoint-dir '{ROOT}/pyproject.toml/run' is invalid: {ROOT}/pyproject.toml is a file",
    ),
]


def test_bad_flags_exit_2_in_one_line_before_ray_is_imported():
    """Each reported in one line naming the flag and the value, no traceback, and Ray never imported:
    one fresh interpreter runs every case in turn (one import of the library instead of one per case)
    and reports, per case, its exit code, whether Ray is imported by then, and what went to stderr."""
    code = (
        "import contextlib, io, json, sys; from copilot_ray import train\n"
        "out = []\n"
        "for argv in json.loads(sys.argv[1]):\n"
        "    err = io.StringIO()\n"
        "    with contextlib.redirect_stderr(err):\n"
        "        try:\n            rc = train.main(argv)\n        except SystemExit as e:\n            rc = e.code\n"
        "    out.append([rc, 'ray' in sys.modules, err.getvalue()])\n"
        "print(json.dumps(out))"
    )
    import json

    argvs = json.dumps([argv for argv, _ in NEWCOMERS_BAD_FLAGS])
    done = subprocess.run([sys.executable, "-c", code, argvs], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    for (argv, message), (rc, ray_imported, err) in zip(
        NEWCOMERS_BAD_FLAGS, json.loads(done.stdout), strict=True
    ):
        assert (rc, ray_imported) == (2, False), (argv, err)
        assert message in err and "Traceback" not in err, (argv, err)


# The README's first example, and the paper's readings (no warm start).
CHECKED = [
    [
        "--layout",
        "four-rooms",
        "--tree-depth",
        "5",
        "--repetitions",
        "5",
        "--stop-env-steps",
        "200000",
        "--check",
    ],
    [
        "--preset",
        "paper_literal",
        "--stop-env-steps",
        "300000",
        "--stop-iters",
        "4",
        "--no-tracking",
        "--check",
    ],
]


def test_check_prints_the_plan_and_the_time_to_expect_and_starts_and_writes_nothing(tmp_path):
    """--check: exit 0 with the plan (the bound on an iteration, the evaluations, the store, the
    checkpoint folder) and the wall time from the measured figures (the warm start's phases x seconds per
    phase + env steps / a lone run's rate), Ray never imported and no file made (one fresh interpreter
    runs both cases in an empty folder)."""
    import json

    from copilot_ray.sweep_spec.estimate import duration_text, measured_rate, measured_warm_start_phase

    code = (
        "import contextlib, io, json, sys; from copilot_ray import train\n"
        "out = []\n"
        "for argv in json.loads(sys.argv[1]):\n"
        "    text = io.StringIO()\n"
        "    with contextlib.redirect_stdout(text):\n"
        "        rc = train.main(argv)\n"
        "    out.append([rc, 'ray' in sys.modules, text.getvalue()])\n"
        "print(json.dumps(out))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, json.dumps(CHECKED)], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    (rc, ray_imported, readme), (rc2, ray_imported2, paper) = json.loads(done.stdout)
    assert (rc, ray_imported, rc2, ray_imported2) == (0, False, 0, False)
    assert list(tmp_path.iterdir()) == []  # no store, no results folder, no console log

    phase, rate = measured_warm_start_phase("copilot")[0], measured_rate("copilot", 1)[0]
    assert "CO-PILOT on maze-point (four-rooms), seed 0" in readme and "K=5" in readme and "b=5" in readme
    assert "an iteration: <= 15,750 env steps (5 repetitions of <= 3,150)" in readme
    assert "evaluations: 100 validation + 100 test tasks after every iteration; >= 13 in the run" in readme
    assert f"MLflow: experiment 'copilot-train' at sqlite:///{tmp_path}/results/train/mlflow.db" in readme
    assert "checkpoint: results/train/maze-point-K5-b5-s0-<start time>/" in readme
    assert "the planner's trees go there too" in readme  # not a folder in ~/ray_results
    assert f"wall time: about {duration_text(1000 * phase + 200_000 / rate)} " in readme
    assert f"1,000 phases x {phase:.2f} s" in readme and "measured_throughput.json" in readme
    # paper_literal: no warm start; 4 iterations end it before its 300k env steps
    assert "preset paper_literal" in paper and "MLflow: none (--no-tracking)" in paper
    assert (
        f"wall time: about {duration_text(4 * 15_750 / rate)} " in paper and "no planner warm start" in paper
    )
    assert " phases x " not in paper
    assert "at most 63,000 env steps" in paper


def test_a_default_results_folder_that_cannot_be_made_is_refused(tmp_path, monkeypatch, capsys):
    """`results` is a file here: the default store and checkpoint folder (results/train) are named."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results").write_text("not a folder")
    assert train.main(["--stop-iters", "1"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        f"error: --tracking-uri 'sqlite:///{tmp_path}/results/train/mlflow.db' (default) is invalid: "
        f"{tmp_path}/results is a file, so no file can be made under it",
        f"error: --checkpoint-dir 'results/train' (default) is invalid: {tmp_path}/results is a file, "
        "so no folder can be made under it",
    ]


def test_an_iteration_line_names_the_test_tasks_it_reads():
    """train's iteration line shows the test tasks' success (a sweep's lines show the validation tasks'),
    and says so."""
    from copilot_ray import keys, train

    result = {keys.TRAINING_ITERATION: 3, keys.SUCCESS_PLANNED: 0.5, keys.SUCCESS_DIRECT: 0.25}
    line = train.progress_line(result, started=0.0)
    assert "test success planned 0.50 direct 0.25" in line


def test_every_problem_is_reported_at_once(capsys):
    assert train.main(["--seed", "-1", "--tree-depth", "99", "--layout", "nope"]) == 2
    err = capsys.readouterr().err
    assert "--seed -1 is invalid" in err and "--tree-depth 99 is invalid" in err and "--layout 'nope'" in err


def test_a_second_run_started_in_the_same_second_gets_its_own_folder(tmp_path, monkeypatch):
    args = train.parse_args(["--layout", "empty", "--seed", "3"])
    config = train.build_config(args)
    monkeypatch.setattr(train.time, "strftime", lambda fmt: "20260101-000000")
    first = train.run_name(args, config, tmp_path)
    assert first == "maze-point-K5-b5-s3-20260101-000000"
    (tmp_path / first).mkdir()
    second = train.run_name(args, config, tmp_path)
    (tmp_path / second).mkdir()
    assert second == first + "+" and train.run_name(args, config, tmp_path) == first + "++"


@pytest.mark.ray
def test_train_with_no_tracking_flag_records_a_run_in_the_default_store(tmp_path):
    """No --tracking-uri: the run is in results/train/mlflow.db, its checkpoint in a folder named after
    it, tagged with its privileges; nothing is written in the home folder (no ~/ray_results)."""
    import mlflow

    tiny = ["--layout", "empty", "--tree-depth", "1", "--repetitions", "1", "--task-batch-size", "2",
            "--tau-max", "5", "--planner-warm-start", "0", "--eval-num-tasks", "5", "--stop-iters", "1",
            "--cost-model-init-euclidean", "500", "--num-steps-sampled-before-learning-starts", "10"]  # fmt: skip
    home = tmp_path / "home"
    home.mkdir()
    env = {**__import__("os").environ, "RAY_AUTH_MODE": "disabled", "HOME": str(home)}
    done = subprocess.run(
        [sys.executable, "-m", "copilot_ray.train", *tiny],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    # quiet: its own first line at once, Ray's and RLlib's notices only in the run's console log
    assert done.stdout.splitlines()[0].startswith("train: training CO-PILOT K=1 b=1 on maze-point (empty)")
    assert "new API stack" not in done.stdout + done.stderr and "gputil" not in done.stdout + done.stderr
    (log,) = (tmp_path / "results" / "train").glob("*.console.log")
    assert "new API stack" in log.read_text() and "gputil" in log.read_text()
    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'results' / 'train' / 'mlflow.db'}")
    exp = client.get_experiment_by_name("copilot-train")
    runs = client.search_runs([exp.experiment_id])
    assert len(runs) == 1 and {r.info.status for r in runs} == {"FINISHED"}
    folders = {p.name for p in (tmp_path / "results" / "train").iterdir() if p.is_dir()}
    for run in runs:
        assert run.info.run_name in folders  # the checkpoint folder, named after the run
        assert run.data.params["checkpoint_dir"].endswith(run.info.run_name)
        assert run.data.tags["copilot.privileges"] == "collision_checks"
    assert list(home.iterdir()) == []
    assert not (tmp_path / "results" / "rllib").exists()  # train's algorithm writes into the run's folder


# A tiny run that checks wiring: one repetition is 2 tasks x 3 sub-tasks x 5 steps = 30 env steps, and
# SAC never updates (learning starts past the run's end).
TINY = ["--layout", "empty", "--tree-depth", "1", "--task-batch-size", "2", "--tau-max", "5",
        "--planner-warm-start", "0", "--eval-num-tasks", "5", "--cost-model-init-euclidean", "500",
        "--num-steps-sampled-before-learning-starts", "10000"]  # fmt: skip


@pytest.mark.ray
def test_sigterm_stops_like_ctrl_c_and_resume_goes_on_in_the_same_run_to_a_repetition_budget(
    ray_session, tmp_path, monkeypatch, capsys
):
    """SIGTERM after the first iteration: a checkpoint, the MLflow run KILLED, exit status 143 (Ray's own
    SIGTERM handler, which exits, is not the one that runs). `--resume` continues that run from its
    checkpoint with a budget of 90 env steps: an iteration is 2 repetitions of 30 here, and the run ends
    at the repetition that reaches the budget (90), not at the end of its iteration (120)."""
    import os
    import signal

    import mlflow

    from copilot_ray import keys

    monkeypatch.chdir(tmp_path)
    shown = train.progress_line

    def sigterm_after_the_first_iteration(result, started):
        if result[keys.TRAINING_ITERATION] == 1:
            os.kill(os.getpid(), signal.SIGTERM)
        return shown(result, started)

    monkeypatch.setattr(train, "progress_line", sigterm_after_the_first_iteration)
    assert train.main([*TINY, "--repetitions", "2", "--stop-iters", "50"]) == train.EXIT_TERMINATED
    out, err = capsys.readouterr()
    lines = out.splitlines()
    assert lines[0].startswith("train: training CO-PILOT K=1 b=2 on maze-point (empty), seed 0")
    assert "evaluating on 5 validation and 5 test tasks" in out  # the heartbeat, inside the iteration
    assert "new API stack" not in out + err  # RLlib's notices: in the log, not on the console
    assert "terminated (SIGTERM): writing a checkpoint" in err
    (folder,) = [p for p in (tmp_path / "results" / "train").iterdir() if p.is_dir()]
    assert "MLflow run" in (folder.parent / f"{folder.name}.console.log").read_text()  # the whole console
    resume = next(line for line in lines if line.startswith("continue it with: "))
    assert resume.endswith(f"-m copilot_ray.train --resume {folder.relative_to(tmp_path)}")
    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'results' / 'train' / 'mlflow.db'}")
    (run,) = client.search_runs([client.get_experiment_by_name("copilot-train").experiment_id])
    assert run.info.status == "KILLED"

    monkeypatch.setattr(train, "progress_line", shown)
    assert train.main(["--resume", str(folder), "--stop-env-steps", "90"]) == 0
    out = capsys.readouterr().out
    assert f"resumed from {folder}: iteration 1, 60 env steps" in out
    (again,) = client.search_runs([run.info.experiment_id])
    assert again.info.run_id == run.info.run_id and again.info.status == "FINISHED"
    history = client.get_metric_history(run.info.run_id, keys.TRAINING_ITERATION)
    assert [(m.step, m.value) for m in history] == [(60, 1.0), (90, 2.0)]


def test_resume_refuses_a_folder_without_a_run_and_flags_of_the_runs_own(tmp_path, capsys):
    assert train.main(["--resume", str(tmp_path)]) == 2
    assert f"--resume {str(tmp_path)!r} is invalid: {tmp_path / train.RUN_FILE} does not exist" in (
        capsys.readouterr().err
    )
    (tmp_path / train.RUN_FILE).write_text("{}")
    assert train.main(["--resume", str(tmp_path), "--tree-depth", "3"]) == 2
    assert "--tree-depth is invalid with --resume" in capsys.readouterr().err


def test_a_first_stop_inside_an_iteration_waits_for_its_boundary_and_a_second_one_stops_at_once():
    """Inside `algo.train()` a first Ctrl-C or SIGTERM asks the algorithm's heartbeat to stop at its next
    boundary (and says so, naming it); a second one raises at once; a warm start paused by the first
    (StopRequested) leaves as the stop it stands for, saying how far it got."""
    import signal

    from copilot_ray.heartbeat import Heartbeat, StopRequested

    stops, beat = train._Stops(), Heartbeat()
    beat.boundary = "the end of this warm-start phase"
    with pytest.raises(train.Terminated, match="paused after 2 of 4 phases"), stops.at_boundaries(beat):
        stops.handle(signal.SIGTERM, None)
        assert beat.stop_requested and beat._stop_message == (
            "terminated (SIGTERM): stopping at the end of this warm-start phase, then writing a checkpoint "
            "(another SIGTERM to stop at once)"
        )
        raise StopRequested("planner warm start paused after 2 of 4 phases")

    stops, beat = train._Stops(), Heartbeat()
    with pytest.raises(KeyboardInterrupt), stops.at_boundaries(beat):
        stops.handle(signal.SIGINT, None)
        assert "(Ctrl-C again to stop at once)" in beat._stop_message
        stops.handle(signal.SIGINT, None)  # the second: at once
    with pytest.raises(KeyboardInterrupt):
        stops.handle(signal.SIGINT, None)  # outside an iteration (Ray's start, the build): at once


@pytest.mark.ray
def test_ctrl_c_pauses_the_warm_start_and_ends_an_iteration_at_a_repetition_so_resume_redoes_nothing(
    ray_session, tmp_path, monkeypatch, capsys
):
    """Ctrl-C after the warm start's 2nd of 4 phases: the run stops at that phase's end, its checkpoint
    holds the 2 phases, and --resume goes on at phase 3. Ctrl-C during the first repetition's traversal:
    the iteration ends when that repetition does (30 env steps, not evaluated: its batch is unfinished),
    and the next --resume takes up the batch's other repetition, so no iteration takes more than the 60
    env steps --check bounds it by and nothing is traversed twice."""
    import os
    import signal

    import mlflow

    from copilot_ray import keys
    from copilot_ray.algorithms.sac.algorithm import GoalSAC
    from copilot_ray.planning.planner_phases import PlannerPhases

    monkeypatch.chdir(tmp_path)
    phase, traverse = PlannerPhases.run, GoalSAC._traverse
    presses = {"phase": 2, "traversal": None}  # the phase after which, the traversal after which

    def phase_then_ctrl_c(self, *args, **kwargs):
        built = phase(self, *args, **kwargs)
        if self.count == presses["phase"]:
            os.kill(os.getpid(), signal.SIGINT)
        return built

    def traverse_then_ctrl_c(self, *args, **kwargs):
        done = traverse(self, *args, **kwargs)
        if presses["traversal"] is not None:
            presses["traversal"] = None
            os.kill(os.getpid(), signal.SIGINT)
        return done

    monkeypatch.setattr(PlannerPhases, "run", phase_then_ctrl_c)
    monkeypatch.setattr(GoalSAC, "_traverse", traverse_then_ctrl_c)
    argv = [*TINY, "--planner-warm-start", "4", "--repetitions", "2", "--stop-iters", "50"]
    assert train.main(argv) == train.EXIT_INTERRUPTED
    out, err = capsys.readouterr()
    assert (
        "interrupted: stopping at the end of this warm-start phase, then writing a checkpoint "
        "(Ctrl-C again to stop at once)"
    ) in out
    assert "interrupted: planner warm start paused after 2 of 4 phases; writing a checkpoint" in err
    (folder,) = [p for p in (tmp_path / "results" / "train").iterdir() if p.is_dir()]

    presses.update(phase=None, traversal=1)
    assert train.main(["--resume", str(folder)]) == train.EXIT_INTERRUPTED
    out, err = capsys.readouterr()
    assert "planner warm start: resuming at phase 3 of 4" in out
    assert "interrupted: stopping at the end of this repetition" in out
    assert "iter    1  env_steps        30" in out and "evaluating" not in out

    assert train.main(["--resume", str(folder), "--stop-env-steps", "60"]) == 0
    out = capsys.readouterr().out
    assert f"resumed from {folder}: iteration 1, 30 env steps" in out and "planner warm start" not in out
    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'results' / 'train' / 'mlflow.db'}")
    (run,) = client.search_runs([client.get_experiment_by_name("copilot-train").experiment_id])
    assert run.info.status == "FINISHED"
    history = client.get_metric_history(run.info.run_id, keys.TRAINING_ITERATION)
    assert [(m.step, m.value) for m in history] == [(30, 1.0), (60, 2.0)]
    evaluated = client.get_metric_history(run.info.run_id, keys.SUCCESS_PLANNED)
    assert [m.step for m in evaluated] == [60]  # the iteration that finished the batch
