"""The experiments copilot_ray writes into are marked as model training (`mlflow.experimentKind`), however
they were made: by a sweep, by `train`, or by someone else before either wrote into them. No Ray."""

from __future__ import annotations

import mlflow

from copilot_ray import tracking

KIND = {tracking.EXPERIMENT_KIND_TAG: tracking.MODEL_TRAINING}


def _tags(uri: str, name: str) -> dict[str, str]:
    return mlflow.MlflowClient(uri).get_experiment_by_name(name).tags


def test_trains_new_experiment_is_model_training(tmp_path):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    tracking.MlflowRun(uri, "one-run", run_name="copilot seed 0", tags={}).end()
    assert KIND.items() <= _tags(uri, "one-run").items()


def test_an_experiment_made_elsewhere_is_marked_when_train_or_a_sweep_writes_into_it(tmp_path):
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    client = mlflow.MlflowClient(uri)
    client.create_experiment("plain", artifact_location=(tmp_path / "a").as_uri())
    client.create_experiment("swept", artifact_location=(tmp_path / "b").as_uri())
    assert tracking.EXPERIMENT_KIND_TAG not in _tags(uri, "plain")
    tracking.MlflowRun(uri, "plain", run_name="copilot seed 0", tags={}).end()
    tracking.open_sweep_run(uri, "swept", "part", resume=True)
    assert KIND.items() <= _tags(uri, "plain").items()
    assert KIND.items() <= _tags(uri, "swept").items()
