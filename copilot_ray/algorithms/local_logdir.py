"""Where an algorithm built outside Tune keeps its files (the Python API's `build_algo()`, `train`).

Ray's Trainable gives an algorithm without Tune's storage a new folder in `~/ray_results` the moment it
is built, whether or not anything is ever written there: every build of the Python API left one in the
home folder. Here such an algorithm's folder is `results/rllib/<class>-<start time>-<pid>-<n>` under
the working directory, where `train` and the sweeps keep theirs, and it is made only when something is
written into it (the planner's trees, `keys.TREES_DIR`). Under Tune nothing changes: the trial's
folder is Tune's.
"""

from __future__ import annotations

import itertools
import os
import time
from pathlib import Path

LOCAL_ROOT = Path("results") / "rllib"  # under the working directory at the build
_builds = itertools.count(1)  # two builds in one second of one process get two folders


class LocalLogdir:
    """Mixed in before RLlib's Algorithm: its folder outside Tune (module docstring)."""

    def _setup_logdir(self) -> None:
        if self._storage:  # a Tune trial: Tune's per-trial folder, as Ray makes it
            super()._setup_logdir()
            return
        name = f"{type(self).__name__}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}-{next(_builds)}"
        self._logdir = str((LOCAL_ROOT / name).absolute())  # made by whoever writes into it

    def log_to(self, folder: str | Path) -> None:
        """Writes the algorithm's files into `folder` from now on (`train`: the run's own folder)."""
        self._logdir = str(Path(folder).absolute())
