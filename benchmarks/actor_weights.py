"""What a stacked act costs per seed against one seed's own: the middle 256 x 256 layer of the actor on
one observation, for one seed's weights, for 16 seeds' as one `torch.bmm`, and as 16 one-seed calls
(one thread), then `SACStep.act` for 16 seeds and the share of its CPU time in `aten::bmm`.

    PYTHONPATH=. python benchmarks/actor_weights.py [--seeds 16] [--rounds 3]

Read: when the bmm's time per seed is about one seed's own call, the stacked act is paying for its
weights (memory), not for the stack's Python.
"""

from __future__ import annotations

import argparse
import time

import torch
from torch.profiler import profile

from benchmarks.stacked_update import _learner, stacked_step


def _us(fn, calls: int = 2000) -> float:
    for _ in range(50):
        fn()
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - start) / calls * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=16, help="seeds in the stack")
    parser.add_argument("--rounds", type=int, default=3, help="times every row runs")
    args = parser.parse_args()
    if args.seeds < 2 or args.rounds < 1:
        parser.error(f"--seeds must be >= 2 and --rounds >= 1, got {args.seeds} and {args.rounds}")
    torch.set_num_threads(1)
    n = args.seeds
    x1, w1, b1 = torch.rand(1, 256), torch.rand(256, 256), torch.rand(256)
    x, w = torch.rand(n, 1, 256), torch.rand(n, 256, 256)
    for r in range(args.rounds):
        one = _us(lambda: torch.nn.functional.linear(x1, w1, b1))
        bmm = _us(lambda: torch.bmm(x, w))
        each = _us(lambda: [torch.nn.functional.linear(x1, w1, b1) for _ in range(n)], calls=500)
        print(
            f"round {r + 1}: one seed's layer {one:.1f} us | {n} seeds' as one bmm {bmm:.1f} us "
            f"({bmm / n:.1f} a seed) | {n} one-seed calls {each:.1f} us",
            flush=True,
        )
    step = stacked_step(_learner("cpu"), n, "cpu")
    obs, noise = torch.rand(n, 1, 4), torch.randn(n, 1, 2)
    print(f"SACStep.act, {n} seeds: {_us(lambda: step.act(obs, noise), calls=300):.1f} us a call", flush=True)
    with profile() as prof:
        for _ in range(50):
            step.act(obs, noise)
    events = prof.key_averages()
    total = sum(e.self_cpu_time_total for e in events)
    share = sum(e.self_cpu_time_total for e in events if e.key == "aten::bmm") / max(total, 1)
    print(f"aten::bmm: {100 * share:.0f} % of SACStep.act's CPU time (50 calls, torch profiler)")


if __name__ == "__main__":
    main()
