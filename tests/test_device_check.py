"""scripts/device_check.sh's structure, cheaply: every step capped and the caps within the call's 8 minutes,
every step that measures a figure present; benchmarks/device_figures.py prints one line for every
figure, measured or why not (skipped, cut at its cap, failed), reads the benchmarks' printed rows, and
writes the GPU rate where `--check` reads it; benchmarks/device_sweep.py's spec, its CPU cut and its rates.
Nothing here starts Ray."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = (ROOT / "scripts" / "device_check.sh").read_text()
sys.path.insert(0, str(ROOT / "benchmarks"))
import device_figures  # noqa: E402
import device_sweep  # noqa: E402


def _steps() -> dict[str, int]:
    block = SCRIPT.split("STEPS=(", 1)[1].split("\n)", 1)[0]
    return {name: int(cap) for name, cap in re.findall(r'"(\w+) (\d+)"', block)}


def test_every_step_is_capped_and_the_caps_fit_the_calls_eight_minutes():
    caps = _steps()
    total = int(re.search(r"^TOTAL=(\d+)", SCRIPT, re.M).group(1))
    assert total <= 8 * 60 and sum(caps.values()) <= total
    assert all(cap >= 15 for cap in caps.values())
    run = set(re.findall(r"^\s*(?:step|skip) (\w+) ", SCRIPT, re.M))
    assert run == set(caps), "a step without a cap, or a cap without a step"
    # every step's command runs under `timeout` (the step function), and nothing else runs long outside
    assert 'timeout --signal INT --kill-after 10 "$((cap - 10))"' in SCRIPT
    # the figures' steps are the script's
    assert {f.step for f in device_figures.FIGURES} <= set(caps)
    # the compile rows come after the trials and the sweep
    order = list(caps)
    assert order.index("compile") > order.index("trials") and order.index("compile") > order.index("sweep")


def test_every_figure_has_a_line_even_when_nothing_ran(tmp_path, capsys):
    assert device_figures.main([str(tmp_path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split(":", 1)[0] for line in lines] == [f"figure {f.key}" for f in device_figures.FIGURES]
    assert all("skipped: no CUDA device" in line or "not reached" in line for line in lines)
    data = json.loads((tmp_path / "device_figures.json").read_text())
    assert [r["key"] for r in data["figures"]] == [f.key for f in device_figures.FIGURES]
    assert data["gpu_section"] is None


def _record(env_steps, wall, evaluation):
    return {
        "env_steps": env_steps,
        "wall_s": wall,
        "updates": env_steps,
        "agent_s": wall - evaluation,
        "agent_updates_s": (wall - evaluation) / 2,
        "planner_s": 0.0,
        "cost_model_s": 0.0,
        "eval_s": evaluation,
    }


def _a_gpu_check(out: Path) -> None:
    """What a check on a GPU would leave: steps, rows, trial iterations, printed benchmark output."""
    steps = [
        {"step": "machine", "cuda": True, "cores": 16},
        {"step": "install", "cap_s": 40, "rc": 0, "seconds": 20},
        {"step": "stacked_update", "cap_s": 40, "rc": 0, "seconds": 30},
        {"step": "trials", "cap_s": 120, "rc": 124, "seconds": 120},
        {"step": "sweep", "cap_s": 150, "rc": 0, "seconds": 140},
        {"step": "pack", "cap_s": 15, "rc": 0, "seconds": 5},
        {"step": "stacked_trial", "cap_s": 45, "rc": 124, "seconds": 45},
        {"step": "compile", "cap_s": 45, "rc": 1, "seconds": 30},
    ]
    (out / "steps.jsonl").write_text("".join(json.dumps(s) + "\n" for s in steps))
    figures = [
        {
            "figure": "update alone",
            "device": "cpu",
            "path": "fused eager",
            "updates_per_s": 40.0,
            "warm_s": 1.0,
        },
        {
            "figure": "update alone",
            "device": "cuda",
            "path": "fused eager",
            "updates_per_s": 400.0,
            "warm_s": 2.0,
        },
        {
            "figure": "update alone",
            "device": "cuda",
            "path": "fused captured",
            "updates_per_s": 2500.0,
            "warm_s": 3.0,
        },
        {"figure": "agreement", "path": "fused captured", "largest_difference": 1e-6, "agrees": True},
        {
            "figure": "update alone",
            "device": "cuda",
            "path": "fused compiled + captured",
            "error": "BackendCompilerFailed: no",
        },
        {
            "source": "device_sweep",
            "trial": "t0",
            "config": 2,
            "seeds": 16,
            "iterations": 8,
            "first_iteration_s": 60.0,
            "seed_env_steps_per_s": 3000.0,
            "done": True,
        },
        {
            "source": "device_sweep",
            "trial": "t1",
            "config": 3,
            "seeds": 16,
            "iterations": 7,
            "first_iteration_s": 61.0,
            "seed_env_steps_per_s": 2000.0,
            "done": True,
        },
    ]
    (out / "figures.jsonl").write_text("".join(json.dumps(r) + "\n" for r in figures))
    rows = [
        ("gpu", 0, _record(1000, 60.0, 5.0), "cuda:0"),
        ("gpu", 0, _record(3000, 10.0, 2.0), "cuda:0"),  # 200 env steps/s, 250 without evaluation
        ("gpu", 1, _record(1000, 60.0, 5.0), "cuda:0"),
        ("gpu", 1, _record(2000, 10.0, 5.0), "cuda:0"),  # 100, 200
        ("cpu baseline", 0, _record(500, 60.0, 5.0), "cpu"),
    ]
    log = "".join(json.dumps({"kind": k, "trial": t, "device": d, **r}) + "\n" for k, t, r, d in rows)
    log += json.dumps({"kind": "cpu before", "trial": 0, "error": "RayActorError: it died"}) + "\n"
    (out / "trials.jsonl").write_text(log)
    (out / "device_check.txt").write_text(
        "# 2026-12-02 10:00 UTC, commit abc1234, 16 cores, NVIDIA H200\n"
        "# cuda: yes (NVIDIA H200 torch 2.11.0)\n"
        "# step stacked_update (cap 40 s, 20 s so far): ...\n"
        "# device cuda (NVIDIA H200), torch 2.11.0, batch 256, networks [256, 256]\n"
        "one seed, fused                   900.0 updates/s       900.0 seed-updates/s\n"
        "1 stacked                         800.0 updates/s       800.0 seed-updates/s\n"
        "1 stacked, captured              3000.0 updates/s      3000.0 seed-updates/s\n"
        "16 stacked                        500.0 updates/s      8000.0 seed-updates/s\n"
        "16 stacked, captured              900.0 updates/s     14400.0 seed-updates/s\n"
        "64 stacked, captured        failed: OutOfMemoryError: CUDA out of memory\n"
        "# step pack (cap 15 s, 300 s so far): ...\n"
        "device_stacked: finished in the store (its Tune folder left out; --resume skips it)\n"
        "# step stacked_trial (cap 45 s, 320 s so far): ...\n"
        "   warm-up iteration: 300 env steps in 12 s\n"
        "   iteration 1: 750.5 env steps/s so far\n"
        "round 1: one seed, its own trial: 750.5 env steps/s\n"
        "   warm-up iteration: 19000 env steps in 30 s\n"
    )
    (out / "device_sweep.tar.gz").write_bytes(b"x" * 1000)


def test_a_checks_folder_gives_each_figure_its_value_or_why_not(tmp_path, capsys):
    _a_gpu_check(tmp_path)
    assert device_figures.main([str(tmp_path)]) == 0
    lines = dict(line.split(": ", 1) for line in capsys.readouterr().out.strip().splitlines())
    assert lines["figure update_gpu_captured"].startswith(
        "the SAC update alone on the GPU, fused captured: 2,500 updates/s"
    )
    assert lines["figure update_gpu_captured"].endswith("[target >= 1,000]")
    assert "agrees (largest parameter difference 1.00e-06)" in lines["figure captured_agrees"]
    assert "14,400 seed-updates/s (900 stacked updates/s; eager 8,000)" in lines["figure stacked_update_16"]
    assert "failed: OutOfMemoryError: CUDA out of memory" in lines["figure stacked_update_64"]
    assert ": 150 env steps/s per trial [target >= 700]" in lines["figure trial_gpu"]  # mean of 200 and 100
    assert ": 225 env steps/s per trial" in lines["figure trial_gpu_without_eval"]
    assert "not reached (cut at 120 s)" in lines["figure trial_cpu_twin"]  # one iteration: no rate
    assert "failed: RayActorError: it died" in lines["figure trial_cpu_before"]
    assert lines["figure trial_gpu_lone"].endswith(": 750 env steps/s [target >= 700]")
    assert lines["figure stacked_64_trial"].endswith(
        "not reached (cut at 45 s); its warm-up iteration took 30 s"
    )
    assert "2,500 seed env steps/s per trial (2 trial(s) of 16 seeds)" in lines["figure stacked_16_trial"]
    assert "failed: BackendCompilerFailed: no" in lines["figure update_gpu_compiled"]
    assert "not reached (step compile exited 1 after 30 s)" in lines["figure compiled_agrees"]
    assert "device_stacked: finished in the store" in lines["figure sweep"]
    data = json.loads((tmp_path / "device_figures.json").read_text())
    section = data["gpu_section"]
    assert section["env_steps_per_s"] == {"copilot": {"side_by_side": 150}}
    assert section["without_evaluation"] == {"copilot": {"side_by_side": 225}}


def test_the_gpu_rate_lands_where_check_reads_it_and_depth_k_gets_a_gpu_plan(tmp_path, monkeypatch):
    from copilot_ray.sweep_spec import estimate, load_specs

    rates = tmp_path / "measured_throughput.json"
    rates.write_text((ROOT / "copilot_ray" / "measured_throughput.json").read_text())
    cpu_rates = json.loads(rates.read_text())["env_steps_per_s"]
    monkeypatch.setattr(device_figures, "THROUGHPUT_FILE", rates)
    monkeypatch.setattr(estimate, "THROUGHPUT_FILE", rates)
    out = tmp_path / "out"
    out.mkdir()
    _a_gpu_check(out)
    monkeypatch.setattr(device_figures, "depth_k_plan", lambda: "wall time: about 1 h (faked)")
    assert device_figures.main([str(out), "--write"]) == 0
    assert json.loads((out / "measured_throughput.json").read_text()) == json.loads(rates.read_text())
    gpu = json.loads(rates.read_text())[estimate.GPU_RATES]
    assert gpu["env_steps_per_s"]["copilot"]["side_by_side"] == 150
    assert json.loads(rates.read_text())["env_steps_per_s"] == cpu_rates  # the CPU's untouched
    (spec,) = load_specs(ROOT / "sweeps" / "depth_k.yaml")
    spec.resources.gpus_per_trial = 0.5
    line = estimate.wall_time_line(spec)
    assert "at ~150 env steps/s per trial side by side" in line and "scripts/device_check.sh at" in line
    # --record, here: the fetched section into this checkout's file
    rates.write_text((ROOT / "copilot_ray" / "measured_throughput.json").read_text())
    assert device_figures.main(["--record", str(out)]) == 0
    assert (
        json.loads(rates.read_text())[estimate.GPU_RATES]["env_steps_per_s"]["copilot"]["side_by_side"] == 150
    )


def test_the_device_sweep_is_a_valid_stacked_gpu_spec_and_its_cpu_cut_is_small(tmp_path):
    from copilot_ray.sweep_spec import load_specs

    (gpu,) = load_specs(ROOT / "sweeps" / "device_stacked.yaml")
    assert gpu.seeds_per_trial == 16 and len(gpu.seeds) == 16 and len(gpu.trial_plan()) == 2
    assert gpu.resources.gpus_per_trial * gpu.resources.max_concurrent_trials <= 1
    path = device_sweep.prepare(tmp_path / "root", cpu=True)
    (cpu,) = load_specs(path)
    assert cpu.resources.gpus_per_trial == 0 and cpu.seeds_per_trial == 2 and cpu.stop.iterations == 2
    assert cpu.name == gpu.name and cpu.searcher == gpu.searcher and cpu.search == gpu.search
    (tmp_path / "root" / "results").mkdir()
    with pytest.raises(SystemExit):  # a root that holds results already is not reused
        device_sweep.prepare(tmp_path / "root", cpu=True)


def test_pack_packs_again_report_only_when_the_archive_could_not_come_back(tmp_path, monkeypatch):
    from copilot_ray import carry

    calls = []

    def fake_carry(argv):
        calls.append(argv)
        Path(argv[1]).write_bytes(b"x" * (100 if "--report-only" in argv else 5000))
        return 0

    monkeypatch.setattr(carry, "main", fake_carry)
    archive = tmp_path / "a.tar.gz"
    assert device_sweep.pack(tmp_path, archive, limit=1000) == 0
    assert [c[-1] for c in calls] == [str(tmp_path), "--report-only"] and archive.stat().st_size == 100
    calls.clear()
    assert device_sweep.pack(tmp_path, archive, limit=10_000) == 0 and len(calls) == 1


def test_the_sweeps_rates_come_from_its_trials_tune_results(tmp_path):
    from copilot_ray import keys

    trial = tmp_path / "results" / "device_stacked" / "tune" / "device_stacked" / "trial_a"
    trial.mkdir(parents=True)
    results = [
        {
            "time_this_iter_s": 60.0,
            keys.SEED_RESULTS: {"0": {keys.ENV_STEPS: 100}, "1": {keys.ENV_STEPS: 100}},
        },
        {
            "time_this_iter_s": 2.0,
            keys.SEED_RESULTS: {"0": {keys.ENV_STEPS: 400}, "1": {keys.ENV_STEPS: 400}},
        },
        {
            "time_this_iter_s": 2.0,
            "done": True,
            "config": {"tree_depth": 2},
            keys.SEED_RESULTS: {"0": {keys.ENV_STEPS: 700}, "1": {keys.ENV_STEPS: 700}},
        },
    ]
    (trial / "result.json").write_text("".join(json.dumps(r) + "\n" for r in results))
    (row,) = device_sweep.trial_rates(tmp_path)
    assert row["seed_env_steps_per_s"] == pytest.approx(1200 / 4) and row["seeds"] == 2
    assert row["first_iteration_s"] == 60.0 and row["done"] and row["config"] == 2
    (line,) = device_sweep.rate_lines([row])
    assert "300 seed env steps/s over 2 iteration(s) after a first of 60 s" in line


def test_the_spec_the_check_runs_is_the_shipped_file():
    data = yaml.safe_load((ROOT / "sweeps" / "device_stacked.yaml").read_text())
    assert data["name"] == device_sweep.NAME
    assert "benchmarks/device_sweep.py prepare" in SCRIPT and "benchmarks/device_sweep.py pack" in SCRIPT


def test_the_device_sweep_cut_packed_and_unpacked_at_its_root_resumes_here(
    ray_session, tmp_path, monkeypatch
):
    """The resume path of the check's sweep, on a CPU with a tiny store: its CPU cut (one configuration,
    2 stacked seeds) Ctrl-C'd at its first result, packed by `carry`, its folder deleted (a new
    machine), unpacked by `device_sweep.py unpack` at the root it names, then `--resume`d there: both
    seeds' MLflow runs FINISHED, every iteration logged once."""
    import shutil

    import mlflow

    from copilot_ray import carry, sweep
    from copilot_ray.keys import ROLE_TAG, ROLE_TRIAL, TRAINING_ITERATION
    from copilot_ray.sweep_spec import load_spec
    from tests import interrupts, stores

    root = tmp_path / "root"
    path = device_sweep.prepare(root, cpu=True, overrides={"search": {"tree_depth": {"grid": [2]}}})
    data = yaml.safe_load(path.read_text())  # a lighter warm start and evaluation: the path is the point
    data["config"].update(planner_warm_start=1, eval_num_tasks=5)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    monkeypatch.chdir(root)  # where the check starts it: its relative storage and store resolve here
    first = sweep.run_sweep(load_spec(path), extra_callbacks=[interrupts.at_result(1)])
    assert first.status == "interrupted"
    out = tmp_path / "carried.tar.gz"
    (state,) = carry.pack(path, out, root)
    assert not state.finished and state.has_tune
    monkeypatch.chdir(tmp_path)
    shutil.rmtree(root)
    stores.forget_open_stores(str(root))

    assert device_sweep.unpack(out) == root
    monkeypatch.chdir(root)
    spec = load_spec(root / "device_stacked.yaml")
    second = sweep.run_sweep(spec, resume=True)
    assert second.status == "finished", second.summary
    assert second.parent_run_id == first.parent_run_id
    client = mlflow.MlflowClient(spec.tracking.uri)
    exp = client.get_experiment_by_name(spec.experiment)
    runs = [r for r in client.search_runs([exp.experiment_id]) if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    assert len(runs) == 2 and {r.info.status for r in runs} == {"FINISHED"}
    for run in runs:
        history = client.get_metric_history(run.info.run_id, TRAINING_ITERATION)
        assert sorted(int(m.value) for m in history) == [1, 2]  # each iteration once, across the cut
