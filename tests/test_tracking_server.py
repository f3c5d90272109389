"""A sweep and its report against a real MLflow tracking server (SQLite backend, local artifact root,
bound to 127.0.0.1): runs, metrics and artifacts all go through the server's HTTP API."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
import yaml

from copilot_ray.keys import CHECKPOINT_ARTIFACT, CONFIG_ARTIFACT, ENV_STEPS, ROLE_TAG, ROLE_TRIAL, TREES_DIR

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.ray


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def mlflow_server(tmp_path):
    port = _free_port()
    artifacts = tmp_path / "server_artifacts"
    mlflow = Path(sys.executable).with_name("mlflow")
    proc = subprocess.Popen(
        [str(mlflow), "server", "--backend-store-uri", f"sqlite:///{tmp_path / 'server.db'}",
         "--artifacts-destination", str(artifacts), "--host", "127.0.0.1", "--port", str(port),
         "--workers", "1"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
        # without MLflow's job runner: seven consumer processes busy for a while, which no run here uses
        env={**os.environ, "MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false"},
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    try:
        # A busy machine (a full suite beside other work) has taken over 60 s to bring it up: wait while
        # the server lives, fail at once if it exits.
        deadline = time.monotonic() + 240
        while True:
            try:
                if urllib.request.urlopen(f"{url}/health", timeout=2).status == 200:
                    break
            except OSError:
                if proc.poll() is not None:
                    pytest.fail(f"the MLflow server exited with {proc.returncode} before it came up")
                if time.monotonic() > deadline:
                    pytest.fail("the MLflow server did not come up within 240 s")
                time.sleep(0.5)
        yield url, artifacts
    finally:
        os.killpg(proc.pid, signal.SIGTERM)  # the server and its workers
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:  # no server outlives its test (its store is a temporary file)
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)


def test_sweep_and_report_through_a_tracking_server(ray_session, tmp_path, mlflow_server, capsys):
    import mlflow

    from analysis.report import main as report_main
    from copilot_ray.sweep import run_sweep
    from copilot_ray.sweep_spec import load_spec

    url, artifacts = mlflow_server
    data = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    data.update(
        tracking={"storage": str(tmp_path / "results")}, stop={"env_steps": 130, "min_evaluations": 1}
    )
    data["search"] = {"tree_depth": {"grid": [1]}}
    path = tmp_path / "smoke.yaml"
    path.write_text(yaml.safe_dump(data))
    outcome = run_sweep(load_spec(path), tracking_uri=url)
    assert outcome.status == "finished" and outcome.tracking_uri == url
    out = capsys.readouterr().out
    assert (
        f"open {url}/#/experiments/" in out and "?workflowType=machine_learning" in out
    )  # the server's own UI

    client = mlflow.MlflowClient(url)
    exp = client.get_experiment_by_name("smoke")
    (trial,) = [r for r in client.search_runs([exp.experiment_id]) if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    assert client.get_metric_history(trial.info.run_id, ENV_STEPS)
    names = {a.path for a in client.list_artifacts(trial.info.run_id)}
    assert {CONFIG_ARTIFACT, CHECKPOINT_ARTIFACT, TREES_DIR} <= names
    # ... and the files are where the server keeps them, not in a local path the client chose
    assert list(artifacts.rglob(f"{trial.info.run_id}/artifacts/{CONFIG_ARTIFACT}"))
    assert not (tmp_path / "results" / "smoke" / "mlruns").exists()

    assert report_main(["smoke", "--tracking-uri", url, "--out", str(tmp_path / "report")]) == 0
    assert list(artifacts.rglob(f"{outcome.parent_run_id}/artifacts/report/success_vs_env_steps.png"))
