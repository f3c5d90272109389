"""ray_cluster.yaml: Ray's own cluster-launcher schema accepts it, and it installs the project as CI does."""

import copy
from pathlib import Path

import jsonschema
import pytest
import yaml
from ray.autoscaler._private.util import prepare_config, validate_config

CLUSTER_YAML = Path(__file__).resolve().parents[1] / "ray_cluster.yaml"


@pytest.fixture(scope="module")
def cluster():
    return yaml.safe_load(CLUSTER_YAML.read_text())


def test_ray_cluster_launcher_accepts_the_file(cluster):
    full = prepare_config(copy.deepcopy(cluster))  # what `ray up` does before validating
    validate_config(full)
    assert full["head_node_type"] in full["available_node_types"]
    assert full["available_node_types"]["cpu_worker"]["max_workers"] >= 1


def test_schema_check_is_not_vacuous(cluster):
    broken = copy.deepcopy(cluster)
    broken["available_node_types"]["head"]["node_confg"] = {}  # misspelt key
    with pytest.raises(jsonschema.ValidationError):
        validate_config(prepare_config(broken))


def test_nodes_install_the_project_like_the_quick_start(cluster):
    assert cluster["file_mounts"]["~/copilot_ray"] == "."
    # setup_env.sh installs torch==2.13.0 before anything else pulls torch in.
    assert any("scripts/setup_env.sh" in cmd for cmd in cluster["setup_commands"])
    # Ray on every node comes from the project's venv, the same version as the sweep driver.
    for cmd in cluster["head_start_ray_commands"] + cluster["worker_start_ray_commands"]:
        assert "~/copilot_ray/.venv/bin/ray" in cmd
