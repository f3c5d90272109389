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
