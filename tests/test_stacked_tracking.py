"""What a stacked trial (spec `seeds_per_trial`) looks like downstream: one MLflow run per seed, tagged,
parametrised and logged as a one-seed trial's run; a seed that failed ends FAILED with its error while
the others finish; a resumed driver finds the runs again and logs no row twice; the sweep's summary has a
row per seed. No Ray: the Tune trial is a stand-in with the attributes the callback reads."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import yaml

from copilot_ray import keys, tracking
from copilot_ray.sweep_spec import load_spec

SEEDS = [3, 5]


def _spec(tmp_path):
    data = {
        "name": "stacked",
        "env": {"id": "maze-point", "config": {"layout": "u-maze"}},
        "algorithm": "copilot",
        "config": {"tree_depth": 2},
        "seeds": SEEDS,
        "seeds_per_trial": 2,
        "searcher": {"type": "grid"},
        "stop": {"iterations": 3},
        "resources": {"num_env_runners": 0},
        "tracking": {"storage": str(tmp_path / "results"), "uri": f"sqlite:///{tmp_path}/store.db"},
    }
    path = tmp_path / "stacked.yaml"
    path.write_text(yaml.safe_dump(data))
    return path, load_spec(path)


def _result(iteration, errors=()):
    """A stacked trial's result as SeedStackTrial reports it: a failed seed keeps its last metrics."""
    per_seed = {}
    for s in SEEDS:
        last = 1 if str(s) in errors else iteration  # (a seed in `errors` failed in iteration 2)
        per_seed[str(s)] = {
            keys.ENV_STEPS: 100.0 * last,
            keys.TRAINING_ITERATION: float(last),
            keys.EVAL_SUCCESS: 0.1 * last + s / 100,
            keys.validation_key(keys.EVAL_SUCCESS): 0.2 * last + s / 100,
        }
    return {keys.SEED_RESULTS: per_seed, keys.SEED_ERRORS: {s: "NonFiniteStateError: boom" for s in errors}}


def test_each_stacked_seed_is_its_own_run_and_a_failed_seed_ends_alone(tmp_path):
    path, spec = _spec(tmp_path)
    uri = spec.tracking.uri
    exp_id, parent, _ = tracking.open_sweep_run(uri, spec.experiment, spec.name, resume=False)
    trial = SimpleNamespace(
        trial_id="t0",
        config={keys.SPEC_PATH_KEY: str(path), keys.SEEDS_KEY: SEEDS},
        status="RUNNING",
        last_result=None,
        checkpoint=None,
        error_file=None,
        path=str(tmp_path / "trial"),
    )
    runs = tracking.TrialRuns(uri, exp_id, spec.name, parent)
    runs.open(trial)
    runs.log_result(trial, _result(1))
    runs.log_result(trial, _result(2, errors=("5",)))

    # a new driver (--resume) finds both runs again; the replayed iteration 2 adds no row
    resumed = tracking.TrialRuns(uri, exp_id, spec.name, parent)
    resumed.open(trial)
    client = tracking._client(uri)
    assert client.get_run(resumed.run_id(trial, 5)).info.status == "FAILED"  # not reopened
    resumed.kill_unfinished([trial])  # an interrupt now: seed 3's run waits KILLED, seed 5's stays FAILED
    assert client.get_run(resumed.run_id(trial, 5)).info.status == "FAILED"
    resumed = tracking.TrialRuns(uri, exp_id, spec.name, parent)
    resumed.open(trial)
    resumed.log_result(trial, _result(2, errors=("5",)))
    resumed.log_result(trial, _result(3, errors=("5",)))
    trial.last_result = {**_result(3, errors=("5",)), "done": True}
    resumed.finish(trial, "FINISHED")

    children = [r for r in client.search_runs([exp_id]) if r.data.tags.get(keys.ROLE_TAG) == keys.ROLE_TRIAL]
    by_seed = {r.data.tags[keys.SEED_TAG]: r for r in children}
    assert sorted(by_seed) == ["3", "5"] and len(children) == 2  # one run per seed, none twice
    for seed, run in by_seed.items():
        assert run.data.params[keys.SEED_PARAM] == seed
        assert run.data.tags[keys.TRIAL_ID_TAG] == "t0"
        assert run.info.run_name.endswith(f"seed {seed}")
    assert by_seed["3"].info.status == "FINISHED"
    assert by_seed["5"].info.status == "FAILED"
    assert by_seed["5"].data.tags[keys.ERROR_TAG] == "NonFiniteStateError: boom"
    steps = {
        s: [m.step for m in client.get_metric_history(r.info.run_id, keys.EVAL_SUCCESS)]
        for s, r in by_seed.items()
    }
    assert steps == {"3": [100, 200, 300], "5": [100]}
    values = [m.value for m in client.get_metric_history(by_seed["3"].info.run_id, keys.EVAL_SUCCESS)]
    assert values == pytest.approx([0.13, 0.23, 0.33])


def test_the_summary_has_a_row_per_stacked_seed(tmp_path):
    import pandas as pd

    from copilot_ray.sweep_summary import rows_from_grid

    path, _ = _spec(tmp_path)
    flat_rows = []
    for iteration in (1, 2):
        result = _result(iteration, errors=("5",) if iteration == 2 else ())
        flat_rows.append({**tracking.flatten(result), keys.EVAL_FRESH: 1.0})
    frame = pd.DataFrame(flat_rows)
    for seed in SEEDS:  # a stacked seed's own fresh flag
        frame[f"{keys.SEED_RESULTS}/{seed}/{keys.EVAL_FRESH}"] = 1.0
    trial = SimpleNamespace(
        trial_id="t0",
        config={keys.SPEC_PATH_KEY: str(path), keys.SEEDS_KEY: SEEDS},
        status="TERMINATED",
        last_result={**_result(2, errors=("5",)), "done": True, keys.TIME_TOTAL_S: 9.0},
    )
    analysis = SimpleNamespace(trials=[trial], trial_dataframes={"t0": frame})
    rows = rows_from_grid(SimpleNamespace(_experiment_analysis=analysis))
    assert [(r.seed, r.status, r.env_steps, r.stacked) for r in rows] == [
        (3, "finished", 200, True),
        (5, "error", 100, True),
    ]
    assert rows[0].config_key == rows[1].config_key == "default"
    success = keys.validation_key(keys.EVAL_SUCCESS)
    assert rows[0].figures[success] == pytest.approx(0.43)  # seed 3's own last evaluation
    assert rows[1].figures[success] == pytest.approx(0.25)  # seed 5's, from before it failed
