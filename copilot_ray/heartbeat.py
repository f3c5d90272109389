"""A line every few seconds about what a long stretch of a run is doing (the planner's warm start, an
iteration's traversal and SAC updates, an evaluation), so that a run is never silent for minutes inside
one iteration. The lines go to the logger `copilot_ray.heartbeat` at INFO: `train` prints them on its
console; in a sweep's trial processes nothing prints them (the sweep prints one line per result).
Standard library only."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

LOGGER_NAME = "copilot_ray.heartbeat"
INTERVAL_S = 10.0  # at most this long between two lines while something is being done


class Heartbeat:
    """`beat(message)` says `message()` when `interval_s` passed since the last line; `say` always does.
    The message is a callable so that a beat that says nothing costs nothing."""

    def __init__(self, interval_s: float = INTERVAL_S, clock: Callable[[], float] = time.monotonic) -> None:
        self.interval_s = interval_s
        self._clock = clock
        self._last = clock()
        self._logger = logging.getLogger(LOGGER_NAME)

    def say(self, message: str) -> None:
        self._last = self._clock()
        self._logger.info(message)

    def beat(self, message: Callable[[], str]) -> None:
        if self._clock() - self._last >= self.interval_s:
            self.say(message())
