"""A run says what it is doing at least every INTERVAL_S inside an iteration, and no more often."""

from __future__ import annotations

import logging

from copilot_ray.heartbeat import INTERVAL_S, LOGGER_NAME, Heartbeat


def test_a_beat_speaks_once_the_interval_passed_and_say_always_speaks(caplog):
    now = [0.0]
    beat = Heartbeat(clock=lambda: now[0])
    asked = []

    def message():
        asked.append(now[0])
        return f"at {now[0]:.0f}"

    with caplog.at_level(logging.INFO, logger=LOGGER_NAME):
        for t in range(0, 35):  # one beat a second for 35 s
            now[0] = float(t)
            beat.beat(message)
        beat.say("evaluating")
    assert [r.getMessage() for r in caplog.records] == ["at 10", "at 20", "at 30", "evaluating"]
    assert asked == [10.0, 20.0, 30.0]  # a beat that says nothing builds no message
    assert INTERVAL_S <= 30
