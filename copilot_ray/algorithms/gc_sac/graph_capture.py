"""A zero-argument function of device tensors replayed from one CUDA graph: one launch per call.

`CapturedCall(fn)` runs `fn` eagerly for its first `warmup` calls (on a side stream, as PyTorch asks
before a capture: the allocator and lazily built state settle there), then captures one call into a
`torch.cuda.CUDAGraph` and from then on replays it. Every call is a real call: the warm-up calls do
their work, and the capturing call replays its graph once right after recording it (recording runs
no kernel).

What `fn` may do: read and write tensors whose storage stays put between calls (parameters,
optimizer state, preallocated buffers, 0-d counters written in place), draw from torch's default
CUDA generator (a graph replay advances its offset), allocate temporaries; not synchronise with the
host (no `.item()`, no data-dependent shapes). Its outputs are the graph's own tensors: each replay
overwrites them, so a caller copies what it keeps. `reset()` drops the graph (after anything that
moves storage, e.g. an optimizer's `load_state_dict`); the next call warms up and captures anew.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch


class CapturedCall:
    """`fn()` replayed from one CUDA graph after `warmup` eager calls (module docstring)."""

    def __init__(self, fn: Callable[[], Any], warmup: int = 3):
        if int(warmup) < 1:
            raise ValueError(f"warmup must be >= 1 (the side-stream calls before the capture), got {warmup}")
        self.fn = fn
        self.warmup = int(warmup)
        self._graph: torch.cuda.CUDAGraph | None = None
        self._out: Any = None
        self._eager_calls = 0

    @property
    def captured(self) -> bool:
        """Whether the next call replays a graph."""
        return self._graph is not None

    def __call__(self) -> Any:
        if self._graph is not None:
            self._graph.replay()
            return self._out
        if self._eager_calls < self.warmup:
            self._eager_calls += 1
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                out = self.fn()
            torch.cuda.current_stream().wait_stream(side)
            return out
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph):
            self._out = self.fn()
        self._graph = graph
        graph.replay()
        return self._out

    def reset(self) -> None:
        """Drops the graph; the next call warms up and captures again."""
        self._graph, self._out, self._eager_calls = None, None, 0
