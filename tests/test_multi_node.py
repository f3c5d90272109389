"""The smoke sweep on a real two-node Ray cluster (Ray's `cluster_utils.Cluster`: two raylets on this
machine, one CPU each), run as a user would, `python -m copilot_ray.sweep SPEC --address ADDR`: its two
trials run side by side, one on each node, and every result reaches MLflow."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from copilot_ray.keys import ENV_STEPS, NODE_ID, ROLE_TAG, ROLE_TRIAL

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


def test_smoke_sweep_uses_both_nodes_of_a_cluster(two_nodes, tmp_path):
    import mlflow

    data = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    data.update(
        tracking={"storage": str(tmp_path / "results")}, stop={"env_steps": 130, "min_evaluations": 1}
    )
    data["resources"] = {"max_concurrent_trials": 2, "num_env_runners": 0}  # one trial per node
    path = tmp_path / "smoke.yaml"
    path.write_text(yaml.safe_dump(data))
    started = time.time()
    out = subprocess.run(
        [sys.executable, "-m", "copilot_ray.sweep", str(path), "--address", two_nodes[0]],
        capture_output=True,
        text=True,
        timeout=400,
        env={**os.environ, "RAY_AUTH_MODE": "disabled"},
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    print(f"two-node smoke sweep: {time.time() - started:.0f} s")

    nodes = set()
    for result_file in (tmp_path / "results" / "smoke" / "tune").rglob("result.json"):
        rows = [json.loads(line) for line in result_file.read_text().splitlines() if line.strip()]
        nodes |= {row[NODE_ID] for row in rows}
    assert nodes == two_nodes[1]  # both nodes ran a trial

    client = mlflow.MlflowClient(f"sqlite:///{tmp_path / 'results' / 'smoke' / 'mlflow.db'}")
    exp = client.get_experiment_by_name("smoke")
    trials = [r for r in client.search_runs([exp.experiment_id]) if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    assert len(trials) == 2 and all(r.info.status == "FINISHED" for r in trials)
    for run in trials:
        assert client.get_metric_history(run.info.run_id, ENV_STEPS)[-1].step >= 130
