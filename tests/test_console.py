"""The quiet console: the known notices of Ray, RLlib, Tune and MLflow (as they were printed by a sweep
and a train run) go to the log only, everything else to the console and the log; a logging record of
several lines is left out whole; `--verbose` installs nothing."""

from __future__ import annotations

import io
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from copilot_ray.console import LIBRARY_NOTICES, is_notice, quiet_console

ROOT = Path(__file__).resolve().parents[1]

# Lines a sweep and a train run printed before the console was quiet (Ray 2.60, MLflow 3).
NOTICES = [
    "2026-11-28 03:37:12,286\tINFO worker.py:2038 -- Started a local Ray instance.",
    "2026-11-28 05:45:01,366\tINFO worker.py:2038 -- Connected to Ray cluster.",
    "2026/11/28 03:37:20 INFO mlflow.store.db.utils: Creating initial MLflow database tables...",
    "2026/11/28 03:37:20 INFO mlflow.store.db.utils: Updating database tables",
    "2026-11-28 03:37:27,787\tWARNING algorithm_config.py:5160 -- You are running CoPilot on the new API "
    "stack! This is the new default behavior for this algorithm.",
    "2026-11-28 03:44:16,206\tWARNING util.py:62 -- Install gputil for GPU system monitoring.",
    "2026-11-28 03:44:16,205\tINFO trainable.py:154 -- Trainable.setup took 19.976 seconds. If your "
    "trainable is slow to initialize, consider setting reuse_actors=True",
    "2026-11-28 03:38:06,135\tINFO tune.py:1007 -- Wrote the latest version of all result files and "
    "experiment state to '/tmp/results/smoke/tune/smoke' in 0.0877s.",
    "To visualize your results with TensorBoard, run: `tensorboard --logdir /tmp/ray/x`",
    # a sweep's --resume, and its Ctrl-C (Tune's own resume hint; the sweep prints its command instead)
    "2026-12-01 23:24:43,025\tINFO tune_controller.py:448 -- Restoring the run from the latest experiment "
    "state file: experiment_state-2026-12-01_23-24-00.json",
    "2026-12-01 23:24:17,268\tWARNING tune.py:1054 -- Experiment has been interrupted, but the most recent "
    'state was saved.\nResume experiment with: Tuner.restore(path="/tmp/results/smoke/tune/smoke", trainable=...)',
    "╭────────────────────────────────────────────────────────╮",
]
OWN = [
    "[088dd_00000] tree_depth=1       K=1 b=1 alpha=paper_per_task seed=0  started",
    "iter    1  env_steps        30  test success planned 0.00 direct 0.00  alpha 0.90  wall     5.7s",
    "| configuration | seeds | validation success |",
    "error: --tracking-uri 'sqlite:///x' is invalid: there is no store file x",
]


@pytest.mark.parametrize("line", NOTICES)
def test_known_notices_are_told_apart(line):
    assert is_notice(line)


@pytest.mark.parametrize("line", OWN)
def test_the_programs_own_lines_are_not_notices(line):
    assert not is_notice(line)


def test_notices_go_to_the_log_and_the_rest_to_both(tmp_path, monkeypatch):
    out, err = io.StringIO(), io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setattr(sys, "stderr", err)
    console = quiet_console(verbose=False)
    print(NOTICES[0])  # before the log's place is known: kept and written there first
    console.log_to(tmp_path / "console.log")
    print(OWN[0])
    # a handler that writes to whatever sys.stderr is when it emits, as Ray's and MLflow's do
    handler = logging.StreamHandler()
    handler.stream = sys.stderr
    log = logging.getLogger("test_console")
    log.addHandler(handler)
    try:
        log.warning(NOTICES[3] + "\nits second line\nits third line")  # one record, several lines
        log.warning(OWN[3])
    finally:
        log.removeHandler(handler)
    print(NOTICES[-1] + "\n│ Search algorithm │")  # Tune's box: one print of several lines
    print(OWN[1])
    console.close()
    assert sys.stdout is out and sys.stderr is err
    assert out.getvalue() == f"{OWN[0]}\n{OWN[1]}\n"
    assert err.getvalue() == f"{OWN[3]}\n"
    logged = (tmp_path / "console.log").read_text()
    for line in (NOTICES[0], NOTICES[3], "its third line", OWN[0], OWN[3], OWN[1], "Search algorithm"):
        assert line in logged
    assert logged.index(NOTICES[0]) < logged.index(OWN[0])


def test_verbose_installs_nothing(monkeypatch):
    from copilot_ray import console

    monkeypatch.setattr(console, "_show_library_notices", False)  # what --verbose turns on, restored
    before = (sys.stdout, sys.stderr)
    assert quiet_console(verbose=True) is None
    assert (sys.stdout, sys.stderr) == before
    assert console._show_library_notices  # the library's notices are shown as well


def test_the_library_leaves_out_its_known_notices_and_keeps_everything_else(tmp_path, monkeypatch):
    """From Python (no quiet console) a known notice is left out and anything else its logger says is
    shown; inside a quiet console the notice reaches the console log."""
    from copilot_ray import console as module

    monkeypatch.setattr(module, "_show_library_notices", False)  # no --verbose in this process
    err = io.StringIO()
    handler = logging.StreamHandler(err)
    name = "ray.rllib.algorithms.sac.sac"
    log = logging.getLogger(name)
    log.addHandler(handler)
    try:
        monkeypatch.setattr(sys, "stderr", io.StringIO())
        notice = "You are running SAC on the new API stack! This is the new default behavior."
        log.warning(notice)
        log.warning("something went wrong")
        assert err.getvalue() == "something went wrong\n"
        console = quiet_console(verbose=False)
        console.log_to(tmp_path / "console.log")
        log.warning(notice)
        console.close()
        assert err.getvalue().endswith(notice + "\n")
    finally:
        log.removeHandler(handler)
    assert name in dict(LIBRARY_NOTICES)


def test_the_python_api_writes_nothing_home_and_prints_no_known_notice(tmp_path):
    """The README's Python API on a fresh machine: no RAY_AUTH_MODE set, HOME a new folder. Building the
    algorithm starts Ray (one CPU) and writes nothing under HOME (no .ray/auth_token, no ray_results
    folder), and none of Ray's or RLlib's known notices reaches the console."""
    script = (
        "import ray\n"
        "from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig\n"
        "ray.init(num_cpus=1, include_dashboard=False)\n"
        "algo = (CoPilotConfig().environment('maze-point', env_config={'layout': 'u-maze'})\n"
        "        .copilot(tree_depth=1, repetitions=1).build_algo())\n"
        "algo.stop()\n"
        "ray.shutdown()\n"
        "print('BUILT')\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "RAY_AUTH_MODE"}
    home, work = tmp_path / "home", tmp_path / "work"
    home.mkdir()
    work.mkdir()
    env.update(HOME=str(home), PYTHONPATH=str(ROOT))
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=work, env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0 and "BUILT" in done.stdout, done.stderr[-3000:]
    assert sorted(p.name for p in home.iterdir()) == []
    said = (done.stdout + done.stderr).splitlines()
    assert [line for line in said if is_notice(line) or "auth" in line.lower()] == []
