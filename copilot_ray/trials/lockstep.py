"""N jobs (one per seed) run one at a time in a fixed order, meeting at rendezvous points: what lets the
seeds of one stacked trial share one update (no Ray, no RLlib).

Each job runs in its own thread, but only the job holding the baton runs: the coordinator hands it to
job 0, 1, ..., N-1 in turn, and a job gives it back when it reaches a rendezvous (`meet(i, request)`),
finishes or raises. Once every unfinished job is parked at a rendezvous, the coordinator calls
`on_round(requests)` once for all of them (the stacked SAC update) and hands each job its answer on its
next turn. So the interleaving is the same on every run, whatever the threads' timing.

Global random state is per job: torch's CPU generator (and its CUDA ones, once CUDA is in use), numpy's
legacy global state and Python's `random` are saved when a job gives the baton back and restored when it takes it again (each job starts from the state it was
built with, `states[i]`). A job therefore draws exactly what it would draw running alone, whatever the
other jobs draw in between: seed i of a stack acts as seed i alone.

A job that raises is finished with its exception (`Outcome.error`); the others go on. A round that
raises fails every job parked at it, each with its own copy of the error (its cause the original).

Why turns rather than parallel threads: a CPU has no parallelism to gain here (the update is one
stacked call, and the env stepping is Python under one lock), and turns make a stack reproducible.
"""

from __future__ import annotations

import copy
import random
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch


@dataclass
class Outcome:
    """What one job ended with: its return value, or the exception it raised."""

    value: Any = None
    error: BaseException | None = None


@dataclass
class RandomState:
    """The process-global random state a job draws from: torch's CPU generator and, where CUDA has been
    initialised, its CUDA generators; numpy's legacy global state; Python's `random`."""

    torch_state: torch.Tensor
    numpy_state: tuple
    python_state: tuple | None = None
    cuda_states: list[torch.Tensor] | None = None

    @classmethod
    def capture(cls) -> RandomState:
        cuda = torch.cuda.get_rng_state_all() if torch.cuda.is_initialized() else None
        return cls(torch.get_rng_state(), np.random.get_state(), random.getstate(), cuda)

    def restore(self) -> None:
        torch.set_rng_state(self.torch_state)
        np.random.set_state(self.numpy_state)
        if self.python_state is not None:
            random.setstate(self.python_state)
        if self.cuda_states is not None and torch.cuda.is_initialized():
            torch.cuda.set_rng_state_all(self.cuda_states)


class Lockstep:
    """Runs jobs in turn with rendezvous points (module docstring).

    `states`: each job's global random state to start from (kept across `run` calls: a job's next
    run continues its own streams). `on_round(requests)`: {job: request} of every job parked at a
    rendezvous -> {job: answer} for some of them (at least one): a job left without an answer stays
    parked, its request in the next round (the stack answers its seeds' actions step by step and their
    updates only once no seed is acting). It runs on the coordinator's thread while every job is
    parked, so it must draw from generators of its own, not the global ones. If it raises, every parked
    job raises that error from `meet`."""

    def __init__(
        self, states: Sequence[RandomState], on_round: Callable[[Mapping[int, Any]], Mapping[int, Any]]
    ):
        self.states = list(states)
        self.on_round = on_round
        self._cond = threading.Condition()
        self._turn: int | None = None  # the job holding the baton (None: the coordinator)
        self._requests: dict[int, Any] = {}
        self._answers: dict[int, Any] = {}

    # ------------------------------------------------------------------ called by a job's thread
    def meet(self, job: int, request: Any) -> Any:
        """Parks job `job` at a rendezvous with `request` and returns its answer once the round ran."""
        with self._cond:
            self._requests[job] = request
            self._give_back(job)
            self._cond.wait_for(lambda: self._turn == job)
            self.states[job].restore()
            answer = self._answers.pop(job)
        if isinstance(answer, Exception):
            raise _own_copy(answer) from answer
        return answer

    def _give_back(self, job: int) -> None:
        self.states[job] = RandomState.capture()
        self._turn = None
        self._cond.notify_all()

    # ------------------------------------------------------------------ the coordinator
    def run(self, jobs: Mapping[int, Callable[[], Any]]) -> dict[int, Outcome]:
        """Runs every job to its end, in turns; {job: Outcome}. The caller's global random state is as
        it was before (the jobs draw from theirs)."""
        callers = RandomState.capture()
        try:
            return self._run(jobs)
        finally:
            callers.restore()

    def _run(self, jobs: Mapping[int, Callable[[], Any]]) -> dict[int, Outcome]:
        outcomes: dict[int, Outcome] = {}
        threads = []

        def body(job: int, fn: Callable[[], Any]) -> None:
            with self._cond:
                self._cond.wait_for(lambda: self._turn == job)
            outcome = Outcome()
            try:  # (a state that cannot be restored fails this job, which still gives the baton back)
                self.states[job].restore()
                outcome.value = fn()
            except BaseException as err:  # noqa: BLE001 - a job's failure is its outcome, not the trial's
                outcome.error = err
            with self._cond:
                outcomes[job] = outcome
                self._give_back(job)

        for job, fn in sorted(jobs.items()):
            thread = threading.Thread(target=body, args=(job, fn), name=f"lockstep-job-{job}", daemon=True)
            thread.start()
            threads.append(thread)
        pending = sorted(jobs)  # the jobs to hand the baton to, in order, this pass
        parked: dict[int, Any] = {}  # requests not answered yet
        while pending or parked:
            for job in pending:
                self._hand(job)
            with self._cond:
                parked.update(self._requests)
                self._requests.clear()
            if not parked:
                break
            requests = dict(sorted(parked.items()))
            try:
                answers = dict(self.on_round(requests))
                if not answers.keys() & requests.keys():
                    raise RuntimeError(
                        f"lockstep: a round answered none of the parked jobs {sorted(requests)}"
                    )
            except Exception as err:  # noqa: BLE001 - handed to every parked job, which raises it
                answers = dict.fromkeys(requests, err)
            pending = [job for job in requests if job in answers]
            with self._cond:
                self._answers.update({job: answers[job] for job in pending})
            for job in pending:
                del parked[job]
        for thread in threads:
            thread.join()
        return outcomes

    def _hand(self, job: int) -> None:
        """Gives job `job` the baton and waits until it is given back."""
        with self._cond:
            self._turn = job
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._turn is None)


def _own_copy(error: Exception) -> Exception:
    """A copy of a round's error for one parked job to raise: the jobs share the error, and raising one
    object from several threads would pile their tracebacks onto it."""
    try:
        return copy.copy(error)
    except Exception:  # noqa: BLE001 - an exception type that cannot be copied: the text, its type named
        return RuntimeError(f"{type(error).__name__}: {error}")
