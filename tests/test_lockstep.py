"""`trials.lockstep.Lockstep`: jobs in turns, one round per rendezvous, per-job random streams, a failing
job stopping alone. No Ray."""

import random
import threading

import numpy as np
import pytest
import torch

from copilot_ray.trials.lockstep import Lockstep, RandomState


def _states(n, base=7):
    states = []
    for i in range(n):
        torch.manual_seed(base + i)
        np.random.seed(base + i)
        random.seed(base + i)
        states.append(RandomState.capture())
    return states


def _job(lockstep, index, meets, log):
    def run():
        got = []
        for k in range(meets[index]):
            log.append(("job", index, k))
            got.append(lockstep.meet(index, (index, k)))
        return got

    return run


def test_jobs_take_turns_in_order_and_every_parked_job_is_in_one_round():
    rounds = []
    log = []

    def on_round(requests):
        rounds.append(sorted(requests))
        log.append(("round", len(rounds)))
        return {job: f"answer {job}.{request[1]}" for job, request in requests.items()}

    meets = {0: 2, 1: 3, 2: 1}
    lockstep = Lockstep(_states(3), on_round)
    outcomes = lockstep.run({i: _job(lockstep, i, meets, log) for i in meets})
    assert rounds == [[0, 1, 2], [0, 1], [1]]  # a job that is done takes no part in later rounds
    assert [o.value for _, o in sorted(outcomes.items())] == [
        ["answer 0.0", "answer 0.1"],
        ["answer 1.0", "answer 1.1", "answer 1.2"],
        ["answer 2.0"],
    ]
    # the interleaving is fixed: every job runs to its rendezvous in order, then the round runs
    assert log == [
        ("job", 0, 0),
        ("job", 1, 0),
        ("job", 2, 0),
        ("round", 1),
        ("job", 0, 1),
        ("job", 1, 1),
        ("round", 2),
        ("job", 1, 2),
        ("round", 3),
    ]


def _draws(lockstep, index, meets):
    def run():
        out = []
        for k in range(meets):
            out.append((torch.rand(3).tolist(), np.random.rand(2).tolist(), random.random()))
            lockstep.meet(index, k)
        out.append((torch.rand(3).tolist(), np.random.rand(2).tolist(), random.random()))
        return out

    return run


def test_each_job_draws_what_it_would_draw_alone():
    """Global torch, numpy and Python `random` draws of job i in a lockstep of three equal its draws running alone
    from the same state, however the others draw in between."""

    def rounds(requests):
        torch.rand(5)  # a round that (wrongly) draws from the globals does not move a job's streams
        random.random()
        return dict.fromkeys(requests)

    together = Lockstep(_states(3), rounds)
    torch.manual_seed(99)
    callers = torch.rand(2)  # the caller's own stream goes on as if no job had run in between
    torch.manual_seed(99)
    torch.rand(1)
    out = together.run({i: _draws(together, i, meets=2 + i) for i in range(3)})
    assert torch.rand(1).item() == callers[1].item()
    for i in range(3):
        alone = Lockstep([_states(3)[i]], rounds)
        assert alone.run({0: _draws(alone, 0, meets=2 + i)})[0].value == out[i].value
    assert out[0].value[0] != out[1].value[0]  # the jobs' streams differ: the check can fail


def test_a_job_that_raises_stops_alone_and_a_failing_round_reaches_every_parked_job():
    def flaky(lockstep):
        def run():
            lockstep.meet(1, "first")
            raise ValueError("job 1 broke")

        return run

    lockstep = Lockstep(_states(2), lambda requests: dict.fromkeys(requests, "ok"))
    meets = {0: 3}
    outcomes = lockstep.run({0: _job(lockstep, 0, meets, []), 1: flaky(lockstep)})
    assert outcomes[0].error is None and outcomes[0].value == ["ok", "ok", "ok"]
    assert isinstance(outcomes[1].error, ValueError) and "job 1 broke" in str(outcomes[1].error)

    def broken_round(requests):
        raise RuntimeError("the stacked update failed")

    lockstep = Lockstep(_states(2), broken_round)
    outcomes = lockstep.run({i: _job(lockstep, i, {0: 1, 1: 1}, []) for i in range(2)})
    for i in range(2):
        with pytest.raises(RuntimeError, match="the stacked update failed"):
            raise outcomes[i].error
    # each job raised its own copy (one object raised in two threads would carry both tracebacks)
    first, second = outcomes[0].error, outcomes[1].error
    assert first is not second and first.__cause__ is second.__cause__
    assert str(first.__cause__) == "the stacked update failed"


def test_a_job_whose_random_state_cannot_be_restored_fails_alone_without_a_hang():
    states = _states(2)
    states[1].torch_state = torch.zeros(3, dtype=torch.uint8)  # not a generator state
    lockstep = Lockstep(states, lambda requests: dict.fromkeys(requests, "ok"))
    outcomes = {}
    runner = threading.Thread(
        target=lambda: outcomes.update(
            lockstep.run({i: _job(lockstep, i, {0: 2, 1: 2}, []) for i in range(2)})
        ),
        daemon=True,
    )
    runner.start()
    runner.join(timeout=30)
    assert not runner.is_alive(), "the lockstep hung on a job that could not start"
    assert outcomes[0].value == ["ok", "ok"]
    assert isinstance(outcomes[1].error, RuntimeError)
