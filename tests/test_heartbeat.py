"""A run says what it is doing at least every INTERVAL_S inside an iteration, and no more often."""

from __future__ import annotations

import logging

import pytest

from copilot_ray.heartbeat import INTERVAL_S, LOGGER_NAME, Heartbeat


def test_a_beat_speaks_once_the_interval_passed_and_say_always_speaks(caplog):
    now = [0.0]
    beat = Heartbeat(clock=lambda: now[0])
    with caplog.at_level(logging.INFO, logger=LOGGER_NAME):
        for t in range(0, 35):  # one beat a second for 35 s
            now[0] = float(t)
            beat.beat(lambda: f"at {now[0]:.0f}")
        beat.say("evaluating")
    assert [r.getMessage() for r in caplog.records] == ["at 10", "at 20", "at 30", "evaluating"]
    assert INTERVAL_S <= 30


def test_a_step_longer_than_the_interval_is_covered_by_the_watcher(caplog):
    """One planner phase that outlasts the interval: the watcher says the latest message again, marked."""
    now = [0.0]
    beat = Heartbeat(clock=lambda: now[0], doing="building the algorithm...")
    with caplog.at_level(logging.INFO, logger=LOGGER_NAME):
        beat.overdue()  # nothing overdue yet
        now[0] = 10.0
        beat.overdue()
        beat.beat(lambda: "planner warm start: phase 14 of 1000")  # noted, not due (just said)
        now[0] = 25.0
        beat.overdue()
        now[0] = 40.0
        beat.overdue()
    assert [r.getMessage() for r in caplog.records] == [
        "building the algorithm... (still)",
        "planner warm start: phase 14 of 1000 (still)",
        "planner warm start: phase 14 of 1000 (still)",
    ]


def test_watched_runs_the_watcher_only_while_the_block_runs(caplog):
    import time

    from copilot_ray.heartbeat import watched

    beat = Heartbeat(interval_s=0.05, doing="waiting")
    with caplog.at_level(logging.INFO, logger=LOGGER_NAME), watched(beat, period_s=0.01):
        time.sleep(0.3)
    said = len(caplog.records)
    time.sleep(0.2)
    assert said >= 2 and len(caplog.records) == said


def test_a_stop_asked_for_is_said_once_by_the_work_not_by_the_asker_and_stays_until_cleared(caplog):
    """`request_stop` may come from a signal handler, which must not write: the message waits for the
    next beat (or the watch), is said once, and the stop stays asked for until `clear_stop`."""
    beat = Heartbeat(interval_s=100.0)
    with caplog.at_level(logging.INFO, logger=LOGGER_NAME):
        beat.request_stop("interrupted: stopping at the end of this repetition")
        assert beat.stop_requested and caplog.records == []
        beat.beat(lambda: "env steps 10")  # not due: only the stop's message
        beat.beat(lambda: "env steps 20")
        beat.request_stop("again")
        beat.overdue()
    assert [r.getMessage() for r in caplog.records] == [
        "interrupted: stopping at the end of this repetition",
        "again",
    ]
    assert beat.stop_requested
    beat.clear_stop()
    assert not beat.stop_requested


def test_show_progress_prints_the_lines_with_the_wall_time_once_per_call(capsys):
    """The Python API's one-liner: heartbeat lines on stdout; a second call replaces the first."""
    from copilot_ray.heartbeat import hide_progress, show_progress

    show_progress()
    show_progress()
    try:
        Heartbeat().say("planner warm start: phase 1 of 1000")
    finally:
        hide_progress()
    Heartbeat().say("not shown")
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("  ... planner warm start: phase 1 of 1000  wall ")


@pytest.mark.ray
def test_the_quick_probe_shows_the_lines_inside_an_iteration_by_default(
    ray_session, tmp_path, monkeypatch, capsys
):
    """benchmarks/maze_learning.py (the README's quick probe, the Python API in one process) prints the
    heartbeat's lines (the warm start's first) without being asked; on a tiny run of one iteration, in the
    test session's Ray."""
    import sys
    from pathlib import Path

    import ray

    from copilot_ray.heartbeat import hide_progress

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import maze_learning

    monkeypatch.setattr(ray, "init", lambda *args, **kwargs: None)  # the session's Ray, left running
    monkeypatch.setattr(ray, "shutdown", lambda: None)
    tiny = ["tree_depth=1", "repetitions=1", "tau_max=5", "planner_warm_start=2", "eval_num_tasks=5",
            "eval_tree_tasks=0", "cost_model.init_euclidean=500", "num_steps_sampled_before_learning_starts=10000"]  # fmt: skip
    argv = ["--layout", "empty", "--env-steps", "30", "--out", str(tmp_path)]
    try:
        maze_learning.main(argv + [item for key in tiny for item in ("--set", key)])
    finally:
        hide_progress()
    out = capsys.readouterr().out
    assert "  ... planner warm start: 2 planner phases on 30 tasks each (no env steps)  wall " in out
    assert "default       s0 it   1 steps      30" in out
