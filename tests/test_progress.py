"""`python -m copilot_ray.progress` reads how far a sweep file got from its store: each part's state,
trials and env steps (counted up to the budget), the whole file's share and the time left."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import pytest
import yaml

from copilot_ray import progress, tracking
from copilot_ray.keys import ENV_STEPS, PARENT_TAG, ROLE_TAG, ROLE_TRIAL, SWEEP_TAG, TIME_TOTAL_S
from copilot_ray.sweep_spec import estimate, load_specs

ROOT = Path(__file__).resolve().parents[1]


# cut's two trials' time_total_s at (env steps): 1,500 env steps in 750 s after their first results
# (2 env steps/s), and 50 s and 10 s of setup before them (a mean of 30 s).
CUT_TIMES = [[(500, 300.0), (1500, 800.0)], [(100, 60.0), (600, 310.0)]]


def _file(tmp_path: Path, with_times: bool = False) -> Path:
    """Three parts of sweeps/smoke.yaml (2 trials of 1,500 env steps each, one at a time), with a store:
    `done` finished (one trial ran 1,700 env steps: past the budget), `cut` stopped with one trial
    finished and one killed at 600 env steps (with `with_times`, its time_total_s: CUT_TIMES), `fresh`
    never started. The store sits under results/, relative."""
    base = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    base["tracking"] = {"storage": "results", "uri": "sqlite:///results/progress.db"}
    path = tmp_path / "three.yaml"
    path.write_text(
        "---\n".join(yaml.safe_dump({**base, "name": n}, sort_keys=False) for n in ("done", "cut", "fresh"))
    )
    (tmp_path / "results").mkdir()
    uri = f"sqlite:///{tmp_path}/results/progress.db"
    done, cut, _ = load_specs(path)
    for spec, trials, finished in (
        (done, [("FINISHED", 1500), ("FINISHED", 1700)], True),
        (cut, [("FINISHED", 1500), ("KILLED", 600)], False),
    ):
        _, parent, _ = tracking.open_sweep_run(uri, spec.experiment, spec.name, resume=False)
        client = tracking._client(uri)
        exp_id = client.get_experiment_by_name(spec.experiment).experiment_id
        for i, (status, steps) in enumerate(trials):
            tags = {SWEEP_TAG: spec.name, ROLE_TAG: ROLE_TRIAL, PARENT_TAG: parent}
            run_id = client.create_run(exp_id, tags=tags).info.run_id
            client.log_metric(run_id, ENV_STEPS, steps, step=steps)
            for at, seconds in CUT_TIMES[i] if with_times and spec.name == "cut" else ():
                client.log_metric(run_id, TIME_TOTAL_S, seconds, step=at)
            client.set_terminated(run_id, status)
        tracking.end_sweep_run(uri, parent, "FINISHED" if finished else "KILLED")
    return path


def test_each_part_its_trials_and_env_steps_and_the_time_left(tmp_path, monkeypatch, capsys):
    rates = tmp_path / "rates.json"
    rates.write_text(json.dumps({"env_steps_per_s": {"copilot": {"lone": 10.0, "side_by_side": 5.0}}}))
    monkeypatch.setattr(estimate, "THROUGHPUT_FILE", rates)
    path = _file(tmp_path)
    assert progress.main([path.name, "--root", str(tmp_path)]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = {line.split()[1]: line for line in out[2:5]}
    assert rows["done"].split()[2:4] == ["finished", "2/0/0"]
    assert rows["done"].endswith("3k / 3k (100 %)")  # 1,500 + 1,700 counted as 1,500 + 1,500
    assert rows["cut"].split()[2:6] == ["running", "or", "stopped", "1/1/0"]
    assert rows["cut"].endswith("2k / 3k (70 %)")  # 1,500 + 600
    assert rows["fresh"].split()[2:5] == ["not", "started", "0/0/2"] and rows["fresh"].endswith(
        "0 / 3k (0 %)"
    )
    # what is left: 30 % of cut's and all of fresh's 2 trials x 1,500 env steps at 10 env steps/s
    with contextlib.chdir(tmp_path):
        left = [progress.part_progress(spec).seconds_left for spec in load_specs(path)]
    assert left == [0.0, pytest.approx(90.0), 300.0]
    assert (
        out[-1]
        == "  1 of 3 parts finished; 5k of 9k env steps (57 %); left: about 6 min (parts paced by --check's rates: 2)"
    )


def test_a_finished_file_says_so_without_an_estimate(tmp_path, capsys):
    path = _file(tmp_path)
    done_only = tmp_path / "done.yaml"
    done_only.write_text(path.read_text().split("---\n")[0])
    assert progress.main([done_only.name, "--root", str(tmp_path)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "  1 of 1 parts finished; 3k of 3k env steps (100 %)"


def test_the_time_left_follows_the_pace_the_trials_ran_at(tmp_path, monkeypatch, capsys):
    """With its trials' time_total_s in the store, a part's time left is its own pace (2 env steps/s
    after the first result, 30 s of setup per new trial), not --check's rate; a part not begun borrows
    that of its algorithm's part with the longest trials."""
    rates = tmp_path / "rates.json"
    rates.write_text(json.dumps({"env_steps_per_s": {"copilot": {"lone": 10.0, "side_by_side": 5.0}}}))
    monkeypatch.setattr(estimate, "THROUGHPUT_FILE", rates)
    path = _file(tmp_path, with_times=True)
    with contextlib.chdir(tmp_path):
        specs = load_specs(path)
        paces = progress.paces_by_algorithm(specs)
        assert paces["copilot"] == progress.Pace(2.0, 30.0, 1500)
        parts = [progress.part_progress(spec, paces) for spec in specs]
    # cut: its killed trial's 900 env steps left (no setup: begun); fresh: 2 x (30 s + 1,500 / 2)
    assert [p.seconds_left for p in parts] == [0.0, pytest.approx(450.0), pytest.approx(1560.0)]
    assert [p.pace_from for p in parts] == [None, progress.OWN, progress.SAME_ALGORITHM]
    assert progress.main([path.name, "--root", str(tmp_path)]) == 0
    assert (
        capsys.readouterr()
        .out.splitlines()[-1]
        .endswith(f"left: about 34 min (parts paced by {progress.OWN}: 1, {progress.SAME_ALGORITHM}: 1)")
    )


def test_bad_input_exits_2_naming_it(tmp_path, capsys):
    assert progress.main(["nowhere.yaml", "--root", str(tmp_path / "absent")]) == 2
    assert "--root" in capsys.readouterr().err
    assert progress.main(["nowhere.yaml", "--root", str(tmp_path)]) == 2
    assert "nowhere.yaml" in capsys.readouterr().err
