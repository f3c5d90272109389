"""The commands the programs print for the user to run next run as printed: they name this install's
Python and MLflow (no activated virtual environment needed), and the MLflow UI command starts without
MLflow's job runner, its page storing the UI's model-training default (copilot_ray.mlflow_app). (The sweep's closing `Report:` command is run in tests/test_sweep.py, on the
store of a sweep that ran.) No Ray."""

from __future__ import annotations

import importlib
import os
import shlex
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from copilot_ray.commands import UI_APP, mlflow, python, python_module
from copilot_ray.mlflow_app import defaults_script
from copilot_ray.store import ui_hint

ROOT = Path(__file__).resolve().parents[1]


def test_commands_name_this_interpreter_relative_to_the_folder_they_are_printed_in(monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    here = Path(sys.executable).absolute()
    assert python() == (str(here.relative_to(ROOT)) if here.is_relative_to(ROOT) else str(here))
    assert python_module("analysis.report", "my exp") == f"{python()} -m analysis.report 'my exp'"
    monkeypatch.chdir(tmp_path)
    assert python() == str(here)  # printed elsewhere: the absolute path
    assert Path(mlflow().split(" -m ")[0]).parent == here.parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _descendants(pid: int) -> list[int]:
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out += [child]
            todo.append(child)
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def test_the_mlflow_ui_command_serves_the_store_as_printed_without_a_job_runner(tmp_path):
    import mlflow as mlflow_library

    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow_library.MlflowClient(uri)
    exp_id = client.create_experiment("printed", artifact_location=(tmp_path / "artifacts").as_uri())
    client.create_run(exp_id, run_name="a run")
    command, then = ui_hint(uri, exp_id)
    assert then.startswith("then open http://127.0.0.1:5000/#/experiments/")
    port = _free_port()  # the printed command on a port no one else uses: only the number changes
    assert " --port 5000 " in command
    ui = subprocess.Popen(
        ["bash", "-c", command.replace(" --port 5000 ", f" --port {port} ")],
        cwd=Path.cwd(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120  # on two busy cores; about 5 s on an idle one
        answer = None
        while answer is None and time.monotonic() < deadline and ui.poll() is None:
            try:
                page = f"http://127.0.0.1:{port}/ajax-api/2.0/mlflow/experiments/get?experiment_id={exp_id}"
                with urllib.request.urlopen(page, timeout=5) as response:
                    answer = response.read().decode()
            except OSError:
                time.sleep(0.5)
        assert answer is not None and '"name": "printed"' in answer.replace('":"', '": "'), ui.poll()
        processes = [_cmdline(p) for p in _descendants(ui.pid)]
        assert not [p for p in processes if "huey" in p], processes
        # its page opens the model-training views, the assistant panel closed, in a browser new to it
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30) as response:
            page = response.read().decode()
        assert f" --app-name {UI_APP} " in command
        assert page.index(defaults_script()) < page.index("static/js/main.")
    finally:
        os.killpg(ui.pid, signal.SIGTERM)
        ui.wait(timeout=30)


def test_the_report_command_a_sweep_prints_imports_in_this_install():
    """`<python> -m analysis.report --help` as the sweep prints it: its imports (pandas among them) are
    this install's."""
    command = python_module("analysis.report", "--help")
    done = subprocess.run(shlex.split(command), cwd=Path.cwd(), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"usage: {python_module('analysis.report')}" in done.stdout


PROGRAMS = ["copilot_ray.sweep", "copilot_ray.train", "copilot_ray.carry", "copilot_ray.progress",
            "copilot_ray.stages", "analysis.report"]  # fmt: skip


@pytest.mark.parametrize("module", PROGRAMS)
def test_a_bad_flag_s_hint_names_this_interpreter(module, capsys):
    """argparse's usage line and train's hint name the program as it runs here (`.venv/bin/python -m
    ...` from a checkout's root), not a plain `python`."""
    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as done:
        main(["--no-such-flag"])
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert f"{python_module(module)} " in err and f" python -m {module}" not in f" {err}", err
