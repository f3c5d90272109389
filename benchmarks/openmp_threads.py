"""OpenMP threads on shared cores: the warm start's planner phase and one SAC update, per thread count and
waiting policy, idle and beside busy processes (docs/measured.md, "OpenMP").

    PYTHONPATH=. .venv/bin/python benchmarks/openmp_threads.py [--phases 15] [--updates 300]

Each cell runs in a fresh process (libgomp reads OMP_WAIT_POLICY once, when torch loads). "busy": two
pure-Python busy loops run beside it; "pair": two copies of the cell run at once. Prints seconds per
planner phase and milliseconds per SAC update.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

CELL = r"""
import os, sys, time
import numpy as np
import torch
threads, phases, updates = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
torch.set_num_threads(threads)
from copilot_ray.algorithms.copilot.settings import SETTINGS
from copilot_ray.envs import make
from copilot_ray.planning.curriculum import CoPilotCurriculum
values = {key: s.default for key, s in SETTINGS.items() if "." not in key}
for target in ("planner", "cost_model"):
    values[target] = {s.field: s.default for s in SETTINGS.values() if s.target == target}
values.update(planner_warm_start=phases, collision_penalty=10.0, alpha_schedule={"kind": "constant", "alpha": 1.0})
env = make("maze-point", layout="four-rooms").unwrapped
rng = np.random.default_rng(0)
cur = CoPilotCurriculum(env, values, env.tasks("train"), env.tasks("test")[0], lambda k: 0.1, rng, 0)
t = time.perf_counter(); cur._warm_start(rng); phase_s = (time.perf_counter() - t) / phases
net = torch.nn.Sequential(torch.nn.Linear(10, 256), torch.nn.ReLU(), torch.nn.Linear(256, 256), torch.nn.ReLU(), torch.nn.Linear(256, 1))
opt = torch.optim.Adam(net.parameters()); x = torch.randn(256, 10)
for i in range(updates + 20):
    if i == 20: t = time.perf_counter()
    loss = net(x).pow(2).mean(); opt.zero_grad(); loss.backward(); opt.step()
print(f"{phase_s:.3f} {(time.perf_counter() - t) / updates * 1e3:.2f}")
"""


def cell(threads: int, policy: str | None, phases: int, updates: int, copies: int = 1) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if policy:
        env["OMP_WAIT_POLICY"] = policy
    # (the cell loads torch before copilot_ray, whose import would set PASSIVE: "unset" is libgomp's default)
    cmd = [sys.executable, "-c", CELL, str(threads), str(phases), str(updates)]
    procs = [
        subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        for _ in range(copies)
    ]
    return [p.communicate()[0].strip() for p in procs]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--phases", type=int, default=15)
    p.add_argument("--updates", type=int, default=300)
    args = p.parse_args()
    print("threads  policy    condition  s/phase  ms/update")
    for condition in ("idle", "busy", "pair"):
        busy = []
        if condition == "busy":
            busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
            time.sleep(0.5)
        try:
            for threads in (2, 1):
                for policy in (None, "PASSIVE"):
                    outs = cell(threads, policy, args.phases, args.updates, 2 if condition == "pair" else 1)
                    for out in outs:
                        phase_s, update_ms = out.split()
                        print(
                            f"{threads:7d}  {policy or 'unset':8s}  {condition:9s}  {phase_s:>7s}  {update_ms:>9s}",
                            flush=True,
                        )
        finally:
            for b in busy:
                b.kill()
                b.wait()


if __name__ == "__main__":
    main()
