"""A trial's GPU share (`resources.gpus_per_trial`), tested on a CPU-only machine: the spec carries it to
RLlib's learner and to Tune's placement group; a local run that asks for GPUs the machine lacks is
refused before Ray starts, and --check says so; 0 (the default) leaves every config as it was."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from copilot_ray.sweep_spec import build_algorithm_config, format_plan, parse_spec

ROOT = Path(__file__).resolve().parents[1]
SPEC = {
    "name": "g",
    "algorithm": "sac",
    "env": {"id": "maze-point", "config": {"layout": "empty"}},
    "config": {"eval_every_env_steps": 500},
    "seeds": [0],
    "stop": {"env_steps": 50000},
}


def _spec(gpus: float | None):
    data = copy.deepcopy(SPEC)
    if gpus is not None:
        data["resources"] = {"gpus_per_trial": gpus}
    return parse_spec(data, "g.yaml")


@pytest.mark.parametrize("algorithm", ["sac", "her", "copilot", "ppo"])
def test_the_share_reaches_the_learner_and_the_trial_bundle(algorithm):
    from copilot_ray.registry import get_algorithm

    data = copy.deepcopy(SPEC)
    data.update(algorithm=algorithm, resources={"gpus_per_trial": 0.25})
    if algorithm == "copilot":
        data["config"]["eval_tree_tasks"] = 1
    spec = parse_spec(data, "g.yaml")
    config = build_algorithm_config(spec.trial_plan()[0], spec)
    assert config.num_gpus_per_learner == 0.25 and config.num_learners == 0
    # The trial's own process holds the learner: its bundle asks Ray for the share.
    trial = get_algorithm(algorithm).trial_class()
    bundles = trial.default_resource_request(config).bundles
    assert bundles[0].get("GPU") == 0.25 and bundles[0]["CPU"] >= 1


def test_no_share_leaves_the_learner_on_the_cpu():
    spec = _spec(None)
    assert spec.resources.gpus_per_trial == 0
    config = build_algorithm_config(spec.trial_plan()[0], spec)
    assert config.num_gpus_per_learner == 0
    assert "GPU(s) per trial" not in format_plan(spec)


def test_a_local_run_asking_for_missing_gpus_is_refused_before_ray(tmp_path, monkeypatch, capsys):
    import sys

    from copilot_ray import sweep
    from copilot_ray.sweep_spec import estimate

    monkeypatch.setattr(estimate, "local_gpus", lambda: 0)
    monkeypatch.setattr(sweep, "local_gpus", lambda: 0)
    data = copy.deepcopy(SPEC)
    data.update(resources={"gpus_per_trial": 1}, tracking={"storage": str(tmp_path / "results")})
    path = tmp_path / "g.yaml"
    path.write_text(yaml.safe_dump(data))
    ray_before = "ray" in sys.modules
    assert sweep.main([str(path)]) == 2
    err = capsys.readouterr().err
    assert "resources.gpus_per_trial=1 is invalid: this machine has 0 GPU(s)" in err
    assert not (tmp_path / "results").exists()
    if not ray_before:
        assert "ray" not in sys.modules
    # --check shows the plan with the share, and the same reason as a warning.
    assert sweep.main([str(path), "--check"]) == 0
    out = capsys.readouterr().out
    assert "1 GPU(s) per trial (the learner)" in out and "warning: resources.gpus_per_trial=1" in out
    # A cluster (--address) is not this machine: its GPUs are its own business.
    assert estimate.gpu_problem(parse_spec(data, "g.yaml"), 1) is None
