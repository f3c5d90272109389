"""benchmarks/device_throughput.py: its rates leave the first iteration out and split the wall time by
phase; bad flags exit 2 naming the flag and value before Ray starts."""

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
