"""A line every few seconds about what a long stretch of a run is doing (the planner's warm start, an
iteration's traversal and SAC updates, an evaluation), so that a run is never silent for minutes inside
one iteration. The lines go to the logger `copilot_ray.heartbeat` at INFO: `train` prints them on its
console, and so does any program that calls `show_progress()` (the Python API, benchmarks); in a sweep's
trial processes nothing prints them (the sweep prints one line per result).

    from copilot_ray.heartbeat import show_progress; show_progress()   # then algo.train() says how far it got

A heartbeat is also how a stop reaches a long iteration: `request_stop(message)` (train's Ctrl-C and
SIGTERM) asks the algorithm to stop at its next boundary (`boundary`: the end of a warm-start phase, of a
repetition, of an evaluation), where its state is whole, so that a checkpoint taken there continues as if
the run had never stopped. Standard library only."""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import TextIO

LOGGER_NAME = "copilot_ray.heartbeat"
INTERVAL_S = 10.0  # at most this long between two lines while something is being done (watched)


class StopRequested(KeyboardInterrupt):
    """Raised where a stop was asked for (`Heartbeat.request_stop`) and the work cannot end early but can
    pause: between two of the planner's warm-start phases. The state is whole there (the planner after
    the phases done, their count, the run's random state), so a checkpoint taken now continues exactly.
    A KeyboardInterrupt, so that RLlib and Tune pass it on as they pass on Ctrl-C."""


class Heartbeat:
    """`beat(message)` notes what is being done and says it when `interval_s` passed since the last
    line; `say` always says. A step that runs longer than the interval between two beats (one planner
    phase on a busy machine, RLlib building the algorithm) is covered by `watched`, whose thread says the
    latest message again. The message is a callable, built at each beat: keep it cheap.

    `request_stop(message)` marks a stop as asked for (`stop_requested`, until `clear_stop`) and says
    `message` at the next beat or watch: it may come from a signal handler, which must not write to a
    stream the main thread may be writing to. Whoever runs the work polls `stop_requested` at its
    boundaries and names the next one in `boundary` (what the asker tells the user)."""

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
        self._latest_at = self._last  # when the latest message was noted
        self._lock = threading.Lock()
        self._logger = logging.getLogger(LOGGER_NAME)
        self._stop = threading.Event()
        self._stop_message: str | None = None  # said by the next beat or watch (not by the asker)
        self.boundary = "the end of this iteration"  # where a stop asked for now takes effect

    # ------------------------------------------------------------------------------- stops
    def request_stop(self, message: str | None = None) -> None:
        """Asks the work to stop at its next boundary; `message` is said soon after, from the work's
        thread or the watch (safe to call from a signal handler: it only sets two fields)."""
        self._stop_message = message
        self._stop.set()

    @property
    def stop_requested(self) -> bool:
        return self._stop.is_set()

    def clear_stop(self) -> None:
        """Forgets a stop asked for (to train on after one)."""
        self._stop.clear()
        self._stop_message = None

    def _say_stop_message(self) -> None:
        with self._lock:  # the work's thread and the watch: said once, not as what is being done
            message, self._stop_message = self._stop_message, None
            if message is not None:
                self._last = self._clock()
        if message is not None:
            self._logger.info(message)

    # ------------------------------------------------------------------------------- lines
    def say(self, message: str) -> None:
        with self._lock:
            self._last = self._latest_at = self._clock()
            self._latest = message
        self._logger.info(message)

    def beat(self, message: Callable[[], str]) -> None:
        self._say_stop_message()
        text = message()
        with self._lock:
            self._latest, self._latest_at = text, self._clock()
            due = self._clock() - self._last >= self.interval_s
        if due:
            self.say(text)

    def overdue(self) -> None:
        """Says the latest message again (marked "still") when the interval passed without a line."""
        self._say_stop_message()
        with self._lock:
            text, now = self._latest, self._clock()
            due = text is not None and now - self._last >= self.interval_s
            still = now - self._latest_at >= self.interval_s  # no beat for a whole interval
        if due:
            self.say(f"{text} (still)" if still and not text.endswith(" (still)") else text)


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
        heartbeat._say_stop_message()  # a stop asked for just before the block ended is still said


class _SinceStart(logging.Formatter):
    """`  ... <message>  wall <seconds since started>s`: train's progress lines' look."""

    def __init__(self, started: float) -> None:
        super().__init__()
        self.started = started

    def format(self, record: logging.LogRecord) -> str:
        return f"  ... {record.getMessage()}  wall {record.created - self.started:7.1f}s"


_SHOWN: dict[
    str, tuple[logging.Handler, int, bool]
] = {}  # show_progress's handler, the logger's level and propagate


def show_progress(stream: TextIO | None = None, started: float | None = None) -> logging.Handler:
    """Prints the heartbeat lines (every few seconds inside a long `algo.train()`: warm-start phases,
    env steps, SAC updates, evaluations) on `stream` (default: stdout), each with the seconds since
    `started` (default: now). A second call replaces the first one's handler; returns the handler
    (`hide_progress` removes it)."""
    hide_progress()
    handler = logging.StreamHandler(sys.stdout if stream is None else stream)
    handler.setFormatter(_SinceStart(time.time() if started is None else started))
    logger = logging.getLogger(LOGGER_NAME)
    _SHOWN["shown"] = (handler, logger.level, logger.propagate)
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False  # the root logger's handlers (Ray's, RLlib's) would print each line again
    return handler


def hide_progress() -> None:
    """Undoes `show_progress` (the logger as it was before)."""
    if "shown" not in _SHOWN:
        return
    handler, level, propagate = _SHOWN.pop("shown")
    logger = logging.getLogger(LOGGER_NAME)
    logger.removeHandler(handler)
    logger.setLevel(level)
    logger.propagate = propagate
