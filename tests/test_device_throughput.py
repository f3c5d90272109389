"""benchmarks/device_throughput.py: its rates leave the first iteration out and split the wall time by
phase; bad flags exit 2 naming the flag and value before Ray starts; --suite is the GPU check in one
command, and without a GPU it skips the GPU trial (and its cores)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import device_throughput  # noqa: E402


def _record(env_steps, wall, updates, agent, agent_updates, evaluation):
    return {
        "env_steps": env_steps,
        "wall_s": wall,
        "updates": updates,
        "agent_s": agent,
        "agent_updates_s": agent_updates,
        "planner_s": 0.0,
        "cost_model_s": 0.0,
        "eval_s": evaluation,
    }


def test_rates_leave_the_first_iteration_out_and_split_the_wall_time():
    records = [
        _record(1_000, 500.0, 900, 100.0, 80.0, 5.0),  # the start: a slow first iteration
        _record(3_000, 10.0, 2_000, 8.0, 6.0, 1.0),
        _record(5_000, 10.0, 2_000, 8.0, 6.0, 1.0),
    ]
    r = device_throughput.rates(records)
    assert r["env_steps_per_s"] == pytest.approx(4_000 / 20)
    assert r["updates_per_s"] == pytest.approx(4_000 / 20)
    assert r["iterations"] == 2 and r["first_iteration_s"] == 500.0
    assert r["shares"]["agent_updates_s"] == pytest.approx(12 / 20)
    assert r["shares"]["agent_s"] == pytest.approx(4 / 20)  # the traversal less its updates
    assert r["shares"]["eval_s"] == pytest.approx(2 / 20)
    assert r["shares"]["other"] == pytest.approx(2 / 20)


@pytest.mark.parametrize(
    "argv, named",
    [
        (["--trials", "0"], "--trials 0"),
        (["--gpus-per-trial", "-1"], "--gpus-per-trial -1.0"),
        (["--trials", "4", "--gpus-per-trial", "0.5"], "--gpus-per-trial 0.5"),
        (["--cpus-per-trial", "10000"], "--cpus-per-trial 10000"),
    ],
)
def test_bad_flags_exit_2_naming_the_flag_and_value(argv, named, capsys):
    with pytest.raises(SystemExit) as done:
        device_throughput.parse_args(argv)
    assert done.value.code == 2
    assert f"error: {named} is invalid" in capsys.readouterr().err


def test_a_cut_off_run_is_summarised_from_its_log(tmp_path, capsys):
    """--log's lines back: per kind, the trials with 2 iterations give the rate, one with a single
    iteration is counted at their mean in the aggregate and said to be so; a kind with no rate says so."""
    import json

    rows = [
        ("gpu", 0, _record(1_000, 60.0, 900, 50.0, 40.0, 5.0)),
        ("gpu", 0, _record(3_000, 20.0, 2_000, 16.0, 12.0, 2.0)),  # 100 env steps/s
        ("gpu", 1, _record(1_000, 60.0, 900, 50.0, 40.0, 5.0)),  # cut off after its first iteration
        ("cpu baseline", 0, _record(1_000, 90.0, 900, 80.0, 60.0, 5.0)),
    ]
    log = tmp_path / "run.jsonl"
    log.write_text(
        "".join(json.dumps({"kind": k, "trial": t, "device": "cuda:0", **r}) + "\n" for k, t, r in rows)
    )
    assert device_throughput.main(["--summarise", str(log), "--budget", "360000"]) == 0
    gpu, shares, cpu = capsys.readouterr().out.strip().splitlines()
    assert gpu.startswith("gpu: 2 trial(s), learner on cuda:0: 100 env steps/s per trial")
    assert (
        "200 in aggregate" in gpu and "2.00 trials/hour" in gpu and "1 trial(s) without 2 iterations" in gpu
    )
    assert "agent_updates 60%" in shares
    assert "per env step 10.00 ms: agent 2.00, agent_updates 6.00" in shares  # 20 s for 2000 env steps
    assert cpu == "cpu baseline: 1 trial(s), learner on cuda:0: no rate (no trial finished 2 iterations)"


def test_summarise_of_a_missing_file_exits_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        device_throughput.parse_args(["--summarise", str(tmp_path / "none.jsonl")])
    assert done.value.code == 2 and "--summarise" in capsys.readouterr().err


def test_suite_sets_its_flags_unless_the_command_line_does(monkeypatch):
    monkeypatch.setattr(device_throughput, "_cuda_available", lambda: True)
    monkeypatch.setattr(device_throughput.os, "cpu_count", lambda: 16)
    args = device_throughput.parse_args(["--suite", "--seconds", "60"])
    assert args.seconds == 60.0  # given: kept
    assert (args.updates_seconds, args.trials, args.gpus_per_trial, args.warm_start) == (8.0, 1, 1.0, 20)
    assert args.cpu_baseline and args.batches_baseline
    plain = device_throughput.parse_args([])
    assert plain.updates_seconds == 0.0 and not plain.batches_baseline and plain.gpus_per_trial == 0.0


def test_without_a_gpu_the_skipped_gpu_trial_takes_no_cores(monkeypatch, capsys):
    monkeypatch.setattr(device_throughput.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(device_throughput, "_cuda_available", lambda: False)
    args = device_throughput.parse_args(["--suite", "--cpus-per-trial", "1"])  # the two CPU trials fit
    assert args.gpus_per_trial == 1.0
    monkeypatch.setattr(device_throughput, "_cuda_available", lambda: True)
    with pytest.raises(SystemExit) as done:  # with a GPU its trial needs a third core
        device_throughput.parse_args(["--suite", "--cpus-per-trial", "1"])
    assert done.value.code == 2 and "trials x CPUs (3) over 2 cores" in capsys.readouterr().err


def test_the_rate_without_evaluation_leaves_the_evaluation_phase_out():
    records = [
        _record(1_000, 500.0, 900, 100.0, 80.0, 5.0),
        _record(3_000, 10.0, 2_000, 6.0, 5.0, 4.0),
        _record(5_000, 10.0, 2_000, 6.0, 5.0, 4.0),
    ]
    r = device_throughput.rates(records)
    assert r["env_steps_per_s"] == pytest.approx(4_000 / 20)
    assert r["env_steps_per_s_without_eval"] == pytest.approx(4_000 / 12)
    line = device_throughput.summary_lines({("gpu", 0): records}, {("gpu", 0): "cuda:0"}, 200_000)[0]
    assert "200 env steps/s per trial (min 200; without evaluation 333)" in line


class _Ref:
    def __init__(self, fn):
        self.fn = fn


class _FakeRay:
    """Enough of ray for run_trials: actors built in this process, results got one at a time."""

    def remote(self, **resources):
        def wrap(cls):
            class Handle:
                def __init__(self, *args):
                    try:
                        self.obj, self.error = cls(*args), None
                    except Exception as exc:  # a real actor fails at its first call
                        self.obj, self.error = None, exc

                def __getattr__(self, name):
                    def call(*a):
                        def run():
                            if self.error is not None:
                                raise self.error
                            return getattr(self.obj, name)(*a)

                        return _Ref(run)

                    return type("M", (), {"remote": staticmethod(call)})

            return type("Remote", (), {"remote": staticmethod(Handle)})

        return wrap

    def get(self, ref):
        return ref.fn()

    def wait(self, refs, num_returns=1):
        return refs[:1], refs[1:]


class _FakeTrial:
    def __init__(
        self, algorithm, layout, eval_every, warm_start, seed, cpus, gpus, kind, log, current, settings
    ):
        assert settings == {"tree_depth": 3}
        if kind == "cpu before":
            raise RuntimeError("could not build\nsecond line")
        self.kind = kind

    def device(self):
        return "cuda:0" if self.kind == "gpu" else "cpu"

    def train_for(self, seconds):
        if self.kind == "gpu":
            raise RuntimeError("CUDA error: an illegal memory access")
        return [_record(1_000, 50.0, 900, 40.0, 30.0, 5.0), _record(3_000, 10.0, 2_000, 8.0, 6.0, 1.0)]


def test_a_trial_that_raises_takes_only_its_own_figures(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", _FakeRay())
    monkeypatch.setattr(device_throughput, "Trial", _FakeTrial)
    args = device_throughput.parse_args(
        ["--seconds", "1", "--log", str(tmp_path / "t.jsonl"), "--set", "tree_depth=3"]
    )
    kinds = [("gpu", 1.0, 1, True), ("cpu baseline", 0.0, 1, True), ("cpu before", 0.0, 1, False)]
    by_trial, devices, errors, _ = device_throughput.run_trials(args, kinds)
    assert errors == {
        ("gpu", 0): "RuntimeError: CUDA error: an illegal memory access",
        ("cpu before", 0): "RuntimeError: could not build",
    }
    lines = device_throughput.summary_lines(by_trial, devices, 200_000, errors)
    assert "gpu: trial 0 failed: RuntimeError: CUDA error" in lines[0]
    assert any(line.startswith("cpu baseline: 1 trial(s), learner on cpu: 200 env steps/s") for line in lines)
    # the log says so too, and reads back the same
    again = device_throughput.read_log(str(tmp_path / "t.jsonl"))
    assert again[2] == errors


def test_update_paths_choose_the_rows_and_each_row_is_a_figure(monkeypatch, tmp_path, capsys):
    import json

    monkeypatch.setattr(device_throughput, "_update_row", lambda d, p, s, t: (f"row {d} {p}", 100.0, 0.5))
    figures = tmp_path / "f.jsonl"
    cuda = pytest.importorskip("torch").cuda.is_available()
    lines = device_throughput.update_rows(1.0, 1, "plain", str(figures))
    rows = [json.loads(line) for line in figures.read_text().splitlines()]
    assert [(r["device"], r["path"]) for r in rows][:2] == [("cpu", "batches"), ("cpu", "fused eager")]
    if not cuda:
        assert (
            lines[0] == "update alone on the GPU: skipped: no CUDA device (torch sees none on this machine)"
        )
        assert len(rows) == 2
        assert device_throughput.update_rows(1.0, 1, "compiled", str(figures)) == [lines[0]]
    assert not device_throughput.parse_args(["--updates-only", "--cpus-per-trial", "10000"]).batches_baseline
