"""The many-machines setup on one machine, run as a user would: a real two-node Ray cluster (Ray's
`cluster_utils.Cluster`: two raylets, one CPU each) and a real MLflow tracking server (SQLite backend,
local artifact root, bound to 127.0.0.1), `python -m copilot_ray.sweep SPEC --address ADDR
--tracking-uri URL`: the smoke sweep's two trials run side by side, one on each node, every run, metric
and artifact goes through the server's HTTP API, and the report reads and writes through it too."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
import yaml

from copilot_ray.keys import (
    CHECKPOINT_ARTIFACT,
    CONFIG_ARTIFACT,
    ENV_STEPS,
    NODE_ID,
    ROLE_SWEEP,
    ROLE_TAG,
    ROLE_TRIAL,
    TREES_DIR,
)
from tests import stores

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.ray


@pytest.fixture
def two_nodes():
    """(address, node ids) of a two-node cluster held by tests/two_node_cluster.py."""
    proc = subprocess.Popen(
        [sys.executable, str(ROOT / "tests" / "two_node_cluster.py")],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        info = json.loads(proc.stdout.readline())
        yield info["address"], set(info["node_ids"])
    finally:
        proc.stdin.close()  # the helper shuts the cluster down
        proc.wait(timeout=120)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def mlflow_server(tmp_path):
    port = _free_port()
    artifacts = tmp_path / "server_artifacts"
    # the session's migrated empty store: the server opens it instead of migrating one of its own
    shutil.copy(stores.migrated_store(), tmp_path / "server.db")
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


def test_smoke_sweep_on_two_nodes_tracked_and_reported_through_a_server(mlflow_server, two_nodes, tmp_path):
    import mlflow

    from analysis.report import main as report_main

    url, artifacts = mlflow_server
    data = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    data.update(
        tracking={"storage": str(tmp_path / "results")}, stop={"env_steps": 130, "min_evaluations": 1}
    )
    data["resources"] = {"max_concurrent_trials": 2, "num_env_runners": 0}  # one trial per node
    path = tmp_path / "smoke.yaml"
    path.write_text(yaml.safe_dump(data))
    started = time.time()
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "copilot_ray.sweep",
            str(path),
            "--address",
            two_nodes[0],
            "--tracking-uri",
            url,
        ],
        capture_output=True,
        text=True,
        timeout=400,
        env={**os.environ, "RAY_AUTH_MODE": "disabled"},
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    print(f"two-node smoke sweep: {time.time() - started:.0f} s")
    # a server's view of the trials: nothing to start, the page to open
    assert f"MLflow UI: open {url}/#/experiments/" in out.stdout
    assert "/runs?viewStateShareKey=trials&compareRunsMode=TABLE&workflowType=machine_learning" in out.stdout
    assert "Connected to Ray cluster" not in out.stdout + out.stderr  # (a notice: in the console log)

    nodes = set()
    for result_file in (tmp_path / "results" / "smoke" / "tune").rglob("result.json"):
        rows = [json.loads(line) for line in result_file.read_text().splitlines() if line.strip()]
        nodes |= {row[NODE_ID] for row in rows}
    assert nodes == two_nodes[1]  # both nodes ran a trial

    client = mlflow.MlflowClient(url)
    exp = client.get_experiment_by_name("smoke")
    runs = client.search_runs([exp.experiment_id])
    trials = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    (parent,) = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_SWEEP]
    assert len(trials) == 2 and all(r.info.status == "FINISHED" for r in trials)
    for trial in trials:
        assert client.get_metric_history(trial.info.run_id, ENV_STEPS)[-1].step >= 130
        names = {a.path for a in client.list_artifacts(trial.info.run_id)}
        assert {CONFIG_ARTIFACT, CHECKPOINT_ARTIFACT, TREES_DIR} <= names
        # ... and the files are where the server keeps them, not in a local path the client chose
        assert list(artifacts.rglob(f"{trial.info.run_id}/artifacts/{CONFIG_ARTIFACT}"))
    assert not (tmp_path / "results" / "smoke" / "mlflow.db").exists()
    assert not (tmp_path / "results" / "smoke" / "mlruns").exists()

    assert report_main(["smoke", "--tracking-uri", url, "--out", str(tmp_path / "report")]) == 0
    assert list(artifacts.rglob(f"{parent.info.run_id}/artifacts/report/success_vs_env_steps.png"))
