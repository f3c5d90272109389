"""A line every few seconds about what a long stretch of a run is doing (the planner's warm start, an
iteration's traversal and SAC updates, an evaluation), so that a run is never silent for minutes inside
one iteration. The lines go to the logger `copilot_ray.heartbeat` at INFO: `train` prints them on its
console; in a sweep's trial processes nothing prints them (the sweep prints one line per result).
Standard library only."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterator

LOGGER_NAME = "copilot_ray.heartbeat"
INTERVAL_S = 10.0  # at most this long between two lines while something is being done (watched)


class Heartbeat:
    """`beat(message)` notes what is being done and says it when `interval_s` passed since the last
    line; `say` always says. A step that runs longer than the interval between two beats (one planner
    phase on a busy machine, RLlib building the algorithm) is covered by `watched`, whose thread says the
    latest message again. The message is a callable, built at each beat: keep it cheap."""

    def __init__(
        self,
        interval_s: float = INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
        doing: str | None = None,
    ) -> None:
        self.interval_s = interval_s
        self._clock = clock
        self._last = clock()
        self._latest = doing
        self._lock = threading.Lock()
        self._logger = logging.getLogger(LOGGER_NAME)

    def say(self, message: str) -> None:
        with self._lock:
            self._last, self._latest = self._clock(), message
        self._logger.info(message)

    def beat(self, message: Callable[[], str]) -> None:
        text = message()
        with self._lock:
            self._latest = text
            due = self._clock() - self._last >= self.interval_s
        if due:
            self.say(text)

    def overdue(self) -> None:
        """Says the latest message again (marked "still") when the interval passed without a line."""
        with self._lock:
            text = self._latest
            due = text is not None and self._clock() - self._last >= self.interval_s
        if due:
            self.say(text if text.endswith(" (still)") else f"{text} (still)")


@contextlib.contextmanager
def watched(heartbeat: Heartbeat, period_s: float = 1.0) -> Iterator[Heartbeat]:
    """While the block runs, a thread of its own looks every `period_s` whether `heartbeat` is overdue."""
    stop = threading.Event()

    def watch() -> None:
        while not stop.wait(period_s):
            heartbeat.overdue()

    thread = threading.Thread(target=watch, name="heartbeat", daemon=True)
    thread.start()
    try:
        yield heartbeat
    finally:
        stop.set()
        thread.join()
