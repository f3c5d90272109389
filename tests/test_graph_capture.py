"""CapturedCall's bookkeeping, with torch.cuda's graph API replaced by a recorder (CI has no GPU): the
first calls run eagerly on a side stream, one call is captured and replayed at once, later calls only
replay, and reset() captures again. On a GPU, benchmarks/device_throughput.py --suite checks that a
captured update agrees with the eager one."""

import contextlib

import pytest
import torch

from copilot_ray.algorithms.gc_sac.graph_capture import CapturedCall


class Recorder:
    """Stands in for torch.cuda's streams and graphs; notes what happens in which order."""

    def __init__(self):
        self.events = []
        self.capturing = False

    def install(self, monkeypatch):
        recorder = self

        class Stream:
            def wait_stream(self, other):
                recorder.events.append("wait")

        class Graph:
            def replay(self):
                recorder.events.append("replay")

        @contextlib.contextmanager
        def on_stream(stream):
            recorder.events.append("side stream")
            yield

        @contextlib.contextmanager
        def capture(graph):
            recorder.capturing = True
            yield
            recorder.capturing = False

        monkeypatch.setattr(torch.cuda, "Stream", Stream)
        monkeypatch.setattr(torch.cuda, "current_stream", lambda: Stream())
        monkeypatch.setattr(torch.cuda, "stream", on_stream)
        monkeypatch.setattr(torch.cuda, "CUDAGraph", Graph)
        monkeypatch.setattr(torch.cuda, "graph", capture)


def test_warm_up_then_one_capture_then_replays_only(monkeypatch):
    recorder = Recorder()
    recorder.install(monkeypatch)
    calls = []

    def fn():
        calls.append("captured" if recorder.capturing else "eager")
        return {"loss": len(calls)}

    step = CapturedCall(fn, warmup=2)
    outs = [step() for _ in range(5)]
    assert calls == ["eager", "eager", "captured"]  # fn's Python runs three times in all
    assert outs[2] is outs[3] is outs[4]  # the graph's own outputs, overwritten by each replay
    assert recorder.events.count("side stream") == 2 and recorder.events.count("replay") == 3
    assert step.captured
    step.reset()
    assert not step.captured
    step(), step(), step()
    assert calls[3:] == ["eager", "eager", "captured"]


def test_a_warm_up_below_one_is_refused():
    with pytest.raises(ValueError, match="warmup must be >= 1"):
        CapturedCall(lambda: None, warmup=0)


def test_the_learners_fused_update_reaches_the_capture_site_with_its_noise_stream_in_place(monkeypatch):
    """On a (faked) CUDA learner the fused update is a `CapturedCall` of the `SACStep`: warmed up, then
    captured once with the step's noise counters and storage as they are, which every replay reads."""
    import gymnasium as gym
    import numpy as np
    from ray.rllib.algorithms.sac import SACConfig
    from ray.rllib.core import DEFAULT_MODULE_ID

    from copilot_ray.algorithms.gc_sac import FlatTransitionBuffer, GCSACTorchLearner, use_fast_learner

    cfg = SACConfig().environment(
        observation_space=gym.spaces.Box(0.0, 1.0, (4,), np.float32),
        action_space=gym.spaces.Box(-1.0, 1.0, (2,), np.float32),
    )
    learner = (
        use_fast_learner(cfg.debugging(seed=0), hidden=(16, 16), torch_threads=1)
        .build_learner_group()
        ._learner
    )
    replay = FlatTransitionBuffer(50, device="cpu")
    rng = np.random.default_rng(0)
    replay.add(
        {
            "obs": rng.uniform(0, 1, (30, 4)).astype(np.float32),
            "new_obs": rng.uniform(0, 1, (30, 4)).astype(np.float32),
            "actions": rng.uniform(-1, 1, (30, 2)).astype(np.float32),
            "rewards": np.full(30, -1.0, np.float32),
            "terminateds": np.zeros(30, bool),
        }
    )
    step = learner.fused_step()
    counters, flat = step.noise.counters, step.flat
    recorder = Recorder()
    recorder.install(monkeypatch)
    monkeypatch.setattr(GCSACTorchLearner, "device", property(lambda self: torch.device("cuda")))
    run = learner._replay_run(DEFAULT_MODULE_ID, replay, 8)
    assert isinstance(run, CapturedCall)
    outs = [run() for _ in range(5)]
    # Three warm-up steps and the capturing one ran the step (the faked recorder computes nothing after).
    assert counters.tolist() == [4 * 8]  # 2 x 8 x 2 normals a step: 8 Philox blocks
    assert run.captured and recorder.events.count("replay") == 2  # after capturing, and the fifth call
    assert outs[3] is outs[4] and set(outs[3]) >= {"qf_loss", "finite", "total_loss"}
    # What the graph holds is the step's own storage: the noise counters and parameters, in place.
    assert learner.fused_step() is step and step.noise.counters is counters and step.flat is flat
