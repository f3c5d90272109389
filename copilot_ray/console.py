"""A quiet console for `train` and `sweep`: the known notices of Ray, RLlib, Tune and MLflow (RLlib's "new
API stack" warnings, MLflow's database setup lines, Tune's file-sync and snapshot notes, the gputil
hint, ...) are kept in a log file instead of the console, so the program's own lines come first.
Everything written to the console is also in that log; `--verbose` shows the notices as well.

It works on what reaches `sys.stdout` / `sys.stderr` (print, and the logging handlers of Ray and MLflow,
which write to whatever `sys.stderr` is when they emit): one write that starts a line is one message
(a logging record is one write, however many lines it has), kept or left out by its first line.
Where the library is used from Python, with no console of these, the same notices that Ray and RLlib log
are left out by filters on their loggers (`leave_out_library_notices`, on the package's import).
Standard library only.
"""

from __future__ import annotations

import logging
import re
import sys
import threading
from pathlib import Path
from typing import TextIO

# The first line of each message the console leaves out (a regular expression searched in it).
NOTICES = tuple(
    re.compile(pattern)
    for pattern in (
        r"You are running \w+ on the new API stack",  # RLlib, once per config built
        r"DeprecationWarning: `RLModule\(config=",  # RLlib's own use of its old RLModule signature
        r"-- Started a local Ray instance",
        r"-- (Connecting to existing Ray cluster at address|Connected to Ray cluster)",
        r"Install gputil for GPU system monitoring",
        r"Trainable\.setup took [\d.]+ seconds",
        r"mlflow\.store\.db\.utils: (Creating initial MLflow database tables|Updating database tables)",
        r"\[alembic\.runtime\.migration\]",
        r"-- Wrote the latest version of all result files and experiment state",
        r"Experiment state snapshotting has been triggered multiple times",
        r"To visualize your results with TensorBoard",
        r"View detailed results here",
        r"Restoring the run from the latest experiment state file",  # Tune, on --resume
        # Tune's own resume hint (`Tuner.restore(path=..., trainable=...)`) on Ctrl-C: the sweep prints
        # the command that resumes it instead
        r"Experiment has been interrupted, but the most recent state was saved",
        r"^[╭│├╰]",  # Tune's box of an experiment's settings
    )
)


# The same notices where the library is used from Python (`CoPilotConfig()...build_algo()`), where no
# quiet console routes them: (the logger that logs it, how its message starts). A filter on each of those
# loggers leaves out exactly these messages; whatever else they log (warnings, errors) is shown.
LIBRARY_NOTICES = (
    ("ray.rllib.algorithms.algorithm_config", r"You are running \w+ on the new API stack"),
    ("ray.rllib.algorithms.algorithm", r"You are running \w+ on the new API stack"),
    ("ray.rllib.algorithms.sac.sac", r"You are running \w+ on the new API stack"),
    ("ray.rllib.algorithms.ppo.ppo", r"You are running \w+ on the new API stack"),
    ("ray._common.deprecation", r"DeprecationWarning: `RLModule\(config="),  # RLlib's own old signature
    ("ray._private.worker", r"Started a local Ray instance"),
    ("ray.tune.trainable.trainable", r"Trainable\.setup took [\d.]+ seconds"),
    ("ray.tune.utils.util", r"Install gputil for GPU system monitoring"),
)
_show_library_notices = False  # --verbose asked to see them


class _LibraryNotice(logging.Filter):
    def __init__(self, pattern: str) -> None:
        super().__init__()
        self._pattern = re.compile(pattern)

    def filter(self, record: logging.LogRecord) -> bool:
        # A quiet console (train, sweep) keeps them in its log; --verbose shows them.
        routed = _show_library_notices or isinstance(sys.stderr, _QuietStream)
        return routed or not self._pattern.match(record.getMessage())


def leave_out_library_notices() -> None:
    """Installs the filters of LIBRARY_NOTICES (once; loggers not yet used are made now, and Ray's modules
    get the same logger objects when they ask for them)."""
    for name, pattern in LIBRARY_NOTICES:
        logger = logging.getLogger(name)
        if not any(isinstance(f, _LibraryNotice) for f in logger.filters):
            logger.addFilter(_LibraryNotice(pattern))


def is_notice(text: str) -> bool:
    first = text.split("\n", 1)[0]
    return any(p.search(first) for p in NOTICES)


class _QuietStream:
    """Stands in for a console stream: every write goes to the log, and to the console unless the
    message it belongs to is a notice."""

    def __init__(self, console: TextIO, log: TextIO) -> None:
        self._console, self._log = console, log
        self._lock = threading.Lock()
        self._at_line_start = True
        self._leaving_out = False

    def write(self, text: str) -> int:
        with self._lock:
            if self._at_line_start and text:
                self._leaving_out = is_notice(text)
            self._log.write(text)
            if not self._leaving_out:
                self._console.write(text)
            if text:
                self._at_line_start = text.endswith("\n")
        return len(text)

    def flush(self) -> None:
        self._log.flush()
        self._console.flush()

    def __getattr__(self, name: str):  # encoding, isatty, fileno, ...: the console's
        return getattr(self._console, name)


class QuietConsole:
    """Installs the quiet streams until `close()`; lines written before `log_to(path)` is known are kept
    in memory and written there first."""

    def __init__(self) -> None:
        self._pending: list[str] = []
        self._log: TextIO = _Pending(self._pending)
        self.path: Path | None = None
        self._saved = (sys.stdout, sys.stderr)
        sys.stdout = _QuietStream(sys.stdout, self)
        sys.stderr = _QuietStream(sys.stderr, self)

    # the log side of both streams
    def write(self, text: str) -> int:
        return self._log.write(text)

    def flush(self) -> None:
        self._log.flush()

    def log_to(self, path: Path) -> None:
        """From now on the log is `path` (appended to: a resumed run adds to its log)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        log = path.open("a", encoding="utf-8")
        log.write("".join(self._pending))
        log.flush()
        self._pending.clear()
        self._log, self.path = log, path

    def close(self) -> None:
        for stream in self._saved:
            stream.flush()
        sys.stdout, sys.stderr = self._saved
        if self.path is not None:
            self._log.close()


class _Pending:
    def __init__(self, lines: list[str]) -> None:
        self._lines = lines

    def write(self, text: str) -> int:
        self._lines.append(text)
        return len(text)

    def flush(self) -> None:
        pass


def quiet_console(verbose: bool) -> QuietConsole | None:
    """The quiet console, installed (None with `verbose`: everything is shown, nothing is logged)."""
    global _show_library_notices
    if verbose:
        _show_library_notices = True
        return None
    return QuietConsole()
