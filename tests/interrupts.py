"""Tune callbacks that press Ctrl-C on a running sweep (SIGINT to this process) at a chosen moment, once.

Once: a resumed Tuner brings its callbacks back from its saved state and must not be cut again, so the
trigger lives in a module-level switch that the first interrupt clears. The classes are module-level so
that Tune's experiment state pickles them by reference. Imports Ray: for Ray tests only.
"""

from __future__ import annotations

import os
import signal

from ray import tune

_ARMED: dict[str, int | bool] = {}


def _press_ctrl_c() -> None:
    _ARMED.clear()
    os.kill(os.getpid(), signal.SIGINT)


class InterruptWhenATrialStartsAfterOneFinished(tune.Callback):
    def on_trial_start(self, iteration, trials, trial, **info):
        if _ARMED.get("after_a_finished_trial") and any(t.status == "TERMINATED" for t in trials):
            _press_ctrl_c()


class InterruptAtResult(tune.Callback):
    def on_trial_result(self, iteration, trials, trial, result, **info):
        if result["training_iteration"] == _ARMED.get("at_result"):
            _press_ctrl_c()


class InterruptAtResultAfterATrialFinished(tune.Callback):
    def on_trial_result(self, iteration, trials, trial, result, **info):
        finished = any(t.status == "TERMINATED" for t in trials)
        if finished and result["training_iteration"] == _ARMED.get("at_result_after_a_finished_trial"):
            _press_ctrl_c()


def when_a_trial_starts_after_one_finished() -> tune.Callback:
    """Cuts a sweep of trials run one at a time in its second trial, the first one done."""
    _ARMED.clear()
    _ARMED["after_a_finished_trial"] = True
    return InterruptWhenATrialStartsAfterOneFinished()


def at_result(training_iteration: int) -> tune.Callback:
    """Cuts a sweep when a trial reports its ``training_iteration``-th result."""
    _ARMED.clear()
    _ARMED["at_result"] = training_iteration
    return InterruptAtResult()


def at_result_after_a_finished_trial(training_iteration: int) -> tune.Callback:
    """Cuts a sweep of trials run one at a time in its second trial, at that trial's
    ``training_iteration``-th result (its checkpoints so far on disk)."""
    _ARMED.clear()
    _ARMED["at_result_after_a_finished_trial"] = training_iteration
    return InterruptAtResultAfterATrialFinished()
