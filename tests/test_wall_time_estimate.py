"""--check's wall-time estimate scales a measured env-steps/s by the budget, in waves of concurrent
trials, and names where that figure was measured (the slot's own source where it has one)."""

from __future__ import annotations

import json

import pytest

from copilot_ray.sweep_spec import estimate, parse_spec


@pytest.fixture
def rates_file(tmp_path, monkeypatch):
    path = tmp_path / "measured_throughput.json"
    path.write_text(
        json.dumps(
            {
                "machine": "2-core CPU, no GPU",
                "source": "old sweep logs",
                "env_steps_per_s": {"sac": {"lone": 50, "side_by_side": 40}},
                "sources": {"sac.side_by_side": "benchmarks/throughput.py --from-store X"},
            }
        )
    )
    monkeypatch.setattr(estimate, "THROUGHPUT_FILE", path)
    return path


def _spec(concurrent: int, seeds: list[int]):
    return parse_spec(
        {
            "name": "est",
            "env": {"id": "maze-point", "config": {"layout": "four-rooms"}},
            "algorithm": "sac",
            "config": {"eval_every_env_steps": 10000},
            "seeds": seeds,
            "stop": {"env_steps": 200000},
            "resources": {"max_concurrent_trials": concurrent, "num_env_runners": 0},
        },
        "est.yaml",
    )


def test_the_estimate_scales_the_measured_rate_and_names_its_source(rates_file):
    side = _spec(2, [0, 1, 2])  # 3 trials, 2 at a time: 2 waves at 40 env steps/s
    assert estimate.wall_seconds(side) == pytest.approx(2 * 200000 / 40)
    line = estimate.wall_time_line(side)
    assert "~40 env steps/s per trial side by side" in line and "--from-store X" in line
    lone = _spec(1, [0])
    assert estimate.wall_seconds(lone) == pytest.approx(200000 / 50)
    assert "old sweep logs" in estimate.wall_time_line(lone)  # no source of its own: the file's


def test_no_measured_rate_no_estimate(rates_file):
    rates_file.write_text(json.dumps({"env_steps_per_s": {}}))
    assert estimate.wall_seconds(_spec(2, [0, 1])) is None
    assert "not estimated" in estimate.wall_time_line(_spec(2, [0, 1]))


def test_how_far_past_the_budget_a_trial_may_run_and_the_comparison_warnings():
    """Tune checks stop.env_steps when an iteration ends; CO-PILOT also ends an iteration between its
    repetitions at the budget or an evaluation point, so it may run one repetition past either (3,150 env
    steps of its 15,750) like SAC one iteration (3,200), and both are evaluated every 10,000. A comparison
    whose parts differ in how far past by more than 5 % of the budget is warned about at --check, and so
    is one whose parts are evaluated at unequal spacing (a repetition of 10 tasks: 15,750 apart)."""
    from copilot_ray.sweep_spec.comparison import overshoot_warnings

    def part(name, algorithm, budget, **config):
        return parse_spec(
            {
                "name": name,
                "experiment": "cmp",
                "env": {"id": "maze-point", "config": {"layout": "four-rooms"}},
                "algorithm": algorithm,
                "config": {"eval_every_env_steps": 10000, **config},
                "seeds": [0],
                "stop": {"env_steps": budget},
                "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
            },
            "cmp.yaml",
        )

    sac, copilot = part("s", "sac", 50000), part("c", "copilot", 50000)
    assert estimate.budget_overshoot(sac) == 3199 and estimate.budget_overshoot(copilot) == 3149
    assert overshoot_warnings([sac, copilot]) == []  # the same overshoot and evaluation spacing
    (evals,) = [e.min_evaluations for e in estimate.trial_estimates(copilot)]
    assert evals == 5  # 50,000 / max(10,000, one repetition of 3,150), not / its 15,750 iteration
    # one repetition of 10 tasks: 15,750 env steps between budget checks
    wide = part("c", "copilot", 50000, repetitions=1, task_batch_size=10)
    assert estimate.budget_overshoot(wide) == 15749
    overshoot, spacing = overshoot_warnings([sac, wide])
    assert "experiment 'cmp'" in overshoot and "s 6 %" in overshoot and "c 31 %" in overshoot
    assert "evaluations may be up to" in spacing and "s 10,000" in spacing and "c 15,750" in spacing
    wide_long = part("c", "copilot", 1_000_000, repetitions=1, task_batch_size=10)
    (only,) = overshoot_warnings([part("s", "sac", 1_000_000), wide_long])
    assert "evaluations may be up to" in only  # a large budget hides the overshoot, not the spacing
    assert overshoot_warnings([sac, part("h", "her", 50000)]) == []


def _gpu_spec():
    data = {
        "name": "est",
        "env": {"id": "maze-point", "config": {"layout": "four-rooms"}},
        "algorithm": "sac",
        "config": {"eval_every_env_steps": 10000},
        "seeds": [0],
        "stop": {"env_steps": 200000},
        "resources": {"max_concurrent_trials": 1, "num_env_runners": 0, "gpus_per_trial": 1},
    }
    return parse_spec(data, "est.yaml")


def test_a_gpu_spec_reads_the_gpu_figure_and_without_one_is_not_estimated(rates_file):
    """A trial on a GPU runs at another rate than on the CPU: its estimate reads the GPU section, names
    that machine, and says where a figure comes from when there is none (never the CPU figure)."""
    spec = _gpu_spec()
    assert estimate.wall_seconds(spec) is None
    line = estimate.wall_time_line(spec)
    assert "not estimated (no env-steps/s measured for sac on a GPU" in line and "device_check.sh" in line
    data = json.loads(rates_file.read_text())
    data["env_steps_per_s_gpu"] = {
        "machine": "one H200, 16 cores",
        "source": "scripts/device_check.sh at abc1234",
        "env_steps_per_s": {"sac": {"lone": 400}},
    }
    rates_file.write_text(json.dumps(data))
    assert estimate.wall_seconds(spec) == pytest.approx(200000 / 400)
    line = estimate.wall_time_line(spec)
    assert (
        "~400 env steps/s per trial" in line
        and "one H200, 16 cores; scripts/device_check.sh at abc1234" in line
    )
    assert estimate.wall_seconds(_spec(1, [0])) == pytest.approx(200000 / 50)  # the CPU spec keeps its figure


def test_the_shipped_rates_name_their_sources_without_a_machines_paths():
    """`--check` prints a rate's source on every machine: a store named by its file, not by the absolute
    path of the worktree it was measured in (which no clone has); `throughput.py --write` records it so."""
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    data = json.loads(estimate.THROUGHPUT_FILE.read_text())
    for key, source in data.get("sources", {}).items():
        assert "sqlite:///" not in source and "/work/" not in source, (key, source)
    sys.path.insert(0, str(root / "benchmarks"))
    try:
        import throughput
    finally:
        sys.path.pop(0)
    argv = ["--from-store", "sqlite:////work/main-at-abc1234/results/x.db", "--concurrent", "2"]
    assert throughput.portable(argv) == ["--from-store", "x.db", "--concurrent", "2"]


def _copilot_spec(concurrent: int, seeds: list[int], **config):
    return parse_spec(
        {
            "name": "est",
            "env": {"id": "maze-point", "config": {"layout": "four-rooms"}},
            "algorithm": "copilot",
            "config": {"eval_every_env_steps": 10000, **config},
            "seeds": seeds,
            "stop": {"env_steps": 200000},
            "resources": {"max_concurrent_trials": concurrent, "num_env_runners": 0},
        },
        "est.yaml",
    )


def test_a_copilot_trial_s_estimate_counts_its_planner_warm_start(rates_file):
    """A CO-PILOT trial spends its warm start before its first env step (1,000 phases at the defaults),
    which the env-step rate leaves out (it is read after the first iteration): `--check` adds it per
    trial, as train --check does, and says so; a spec without a warm start adds nothing."""
    data = json.loads(rates_file.read_text())
    data["env_steps_per_s"]["copilot"] = {"lone": 80, "side_by_side": 100}
    data["warm_start_s_per_phase"] = {"copilot": 0.25}
    rates_file.write_text(json.dumps(data))
    side = _copilot_spec(2, [0, 1, 2])  # 2 waves, each a warm start of 1,000 x 0.25 s and 200k at 100/s
    assert estimate.wall_seconds(side) == pytest.approx(2 * (1000 * 0.25 + 200000 / 100))
    line = estimate.wall_time_line(side)
    assert "per trial side by side + the warm start's 1,000 phases x 0.25 s = 4 min;" in line, line
    assert "the warm start: measured_throughput.json's copilot.warm_start_s_per_phase" in line
    cold = _copilot_spec(1, [0], planner_warm_start=0)
    assert estimate.wall_seconds(cold) == pytest.approx(200000 / 80)
    assert "warm start" not in estimate.wall_time_line(cold)
    # a grid over the warm start: the mean over its configurations
    grid = parse_spec(
        {
            "name": "est",
            "env": {"id": "maze-point", "config": {"layout": "four-rooms"}},
            "algorithm": "copilot",
            "config": {"eval_every_env_steps": 10000},
            "search": {"planner_warm_start": {"grid": [0, 2000]}},
            "seeds": [0],
            "stop": {"env_steps": 200000},
            "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
        },
        "est.yaml",
    )
    assert estimate.wall_seconds(grid) == pytest.approx(2 * (1000 * 0.25 + 200000 / 80))
    del data["warm_start_s_per_phase"]  # no figure: the env steps alone, and the line says so
    rates_file.write_text(json.dumps(data))
    assert estimate.wall_seconds(side) == pytest.approx(2 * 200000 / 100)
    assert "warm start not counted" in estimate.wall_time_line(side)
