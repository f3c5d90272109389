"""The planner-only probe (`benchmarks/planner_collision.py`) and its many-process runner: it chooses
defaults, so it scores the validation tasks and never asks for the test tasks; each evaluation is logged
and the logs of several processes summarise into one row per layout and variant."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from copilot_ray.envs.maze.env import GoalMazeEnv

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # as tests/test_device_throughput.py imports its benchmark

import planner_collision  # noqa: E402


def test_the_probe_scores_validation_tasks_and_logs_each_evaluation(tmp_path, monkeypatch, capsys):
    asked = []
    tasks = GoalMazeEnv.tasks

    def recording_tasks(self, split):
        asked.append(split)
        return tasks(self, split)

    monkeypatch.setattr(GoalMazeEnv, "tasks", recording_tasks)
    log = tmp_path / "probe.jsonl"
    argv = ["planner_collision.py", "--collision-costs", "indicator", "--iterations", "4", "--eval-every", "2",
            "--layout", "u-maze", "--seeds", "3", "--max-kl", "0.5", "--task-batch-size", "4",
            "--num-samples", "2", "--log", str(log)]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    planner_collision.main()
    assert "test" not in asked and {"train", "validation"} <= set(asked)
    records = [json.loads(line) for line in log.read_text().splitlines()]
    assert [r["phase"] for r in records] == [2, 4]
    for r in records:
        assert r["layout"] == "u-maze" and r["seed"] == 3 and "max_kl 0.5" in r["variant"]
        assert 0.0 <= r["collision_free"] <= 1.0 and r["kl_max"] >= 0.0 and r["rolled_back"] >= 0
    # a second process's log of another seed: one row, two seeds, the last evaluation of each
    other = tmp_path / "other.jsonl"
    other.write_text(json.dumps({**records[-1], "seed": 7, "collision_free": 0.25, "kl_max": 1e6}) + "\n")
    capsys.readouterr()
    planner_collision.summarise([str(log), str(other)])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| u-maze")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    assert cells[2:4] == ["2", "4"]  # seeds, phases
    assert f"s3 {records[-1]['collision_free']:.2f}" in cells[5] and "s7 0.25" in cells[5]
    assert cells[-1] == "1"  # one seed's update KL went above 100


def _runner_calls(tmp_path, **env_vars):
    """Run the runner with a stand-in interpreter that records its arguments; the probe runs it started."""
    tmp_path.mkdir()
    calls = tmp_path / "calls.txt"
    fake = tmp_path / "python"
    fake.write_text(f'#!/usr/bin/env bash\necho "$*" >> {calls}\n')
    fake.chmod(0o755)
    out = tmp_path / "out"
    done = subprocess.run(
        ["bash", "benchmarks/planner_validation_probe.sh", "10", str(out), "60"],
        cwd=ROOT,
        env={**os.environ, "PYTHON": str(fake), **env_vars},
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    lines = [line for line in calls.read_text().splitlines() if line != "--version"]  # the banner's
    assert lines[-1].endswith(f"--summarise {out}/probe.jsonl")
    runs = set()
    for line in lines[:-1]:
        argv = line.split()
        flags = dict(zip(argv[1::2], argv[2::2], strict=False))  # argv[0] is the script
        assert argv[0] == "benchmarks/planner_collision.py" and flags["--iterations"] == "10"
        kind = ("k" if "--max-kl" in flags else "d") if "--std-final" in flags else "c"
        if flags["--collision-costs"] == "length":
            kind = "l" if kind == "d" else "?"
        if flags["--mean"] != "free":  # always explicit: the benchmark's own default follows CO-PILOT's
            kind = {"squashed": "s", "leaky": "b"}[flags["--mean"]] if kind == "d" else "?"
        runs.add((flags["--layout"], kind, int(flags["--seeds"])))
    assert len(runs) == len(lines) - 1  # each once
    return runs


def test_the_runner_starts_each_layout_variant_and_seed_once(tmp_path):
    """28 probe runs by default (four-rooms and u-maze: 3 variants x 4 seeds; spiral: 2 x 2), then one
    summary of the runs' logs; VARIANTS / SPIRAL_VARIANTS choose others (l: the graded collision cost, s: a
    squashed mean, b: a leaky one)."""
    expected = {(lay, v, s) for lay in ("four-rooms", "u-maze") for v in "dck" for s in range(4)}
    expected |= {("spiral", v, s) for v in "dk" for s in range(2)}
    assert _runner_calls(tmp_path / "a") == expected
    chosen = {(lay, "l", s) for lay in ("four-rooms", "u-maze") for s in range(4)} | {
        ("spiral", "l", 0),
        ("spiral", "l", 1),
    }
    assert _runner_calls(tmp_path / "b", VARIANTS="l", SPIRAL_VARIANTS="l") == chosen
    squashed = {(lay, "s", s) for lay in ("four-rooms", "u-maze") for s in range(4)}
    assert _runner_calls(tmp_path / "c", VARIANTS="s", SPIRAL_VARIANTS="") == squashed
    leaky = {("spiral", "b", 0), ("spiral", "b", 1)}
    assert _runner_calls(tmp_path / "d", VARIANTS="", SPIRAL_VARIANTS="b") == leaky
