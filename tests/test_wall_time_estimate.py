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


def test_how_far_past_the_budget_a_trial_may_run_and_the_comparison_warning():
    """Tune checks stop.env_steps when an iteration ends: a part whose iterations are large may run that
    much further (CO-PILOT's iterations of up to 15,750 env steps against SAC's 3,200); a comparison whose
    parts differ in it by more than 5 % of the budget is warned about at --check."""
    from copilot_ray.sweep_spec.comparison import overshoot_warnings

    def part(name, algorithm, budget):
        return parse_spec(
            {
                "name": name,
                "experiment": "cmp",
                "env": {"id": "maze-point", "config": {"layout": "four-rooms"}},
                "algorithm": algorithm,
                "config": {"eval_every_env_steps": 10000},
                "seeds": [0],
                "stop": {"env_steps": budget},
                "resources": {"max_concurrent_trials": 1, "num_env_runners": 0},
            },
            "cmp.yaml",
        )

    sac, copilot = part("s", "sac", 50000), part("c", "copilot", 50000)
    assert estimate.budget_overshoot(sac) == 3199 and estimate.budget_overshoot(copilot) == 15749
    (warning,) = overshoot_warnings([sac, copilot])
    assert "experiment 'cmp'" in warning and "s 6 %" in warning and "c 31 %" in warning
    assert overshoot_warnings([part("s", "sac", 1_000_000), part("c", "copilot", 1_000_000)]) == []
