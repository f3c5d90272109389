"""Seconds per planner warm-start phase, as `python -m copilot_ray.train` runs it: CO-PILOT's curriculum at
its defaults (K = 5, 30 tasks per phase, `planner.num_samples` trees per task) on maze-point, one torch
thread, no Ray. `train --check` multiplies this figure by `planner_warm_start` (1000 by default).

    PYTHONPATH=. .venv/bin/python benchmarks/warm_start.py [--phases 200] [--layout four-rooms]
        [--busy-core] [--write]

Prints the wall seconds per phase and the CPU seconds of this process per phase: on a machine that
others share, the CPU figure is what a phase takes with a core of its own (the one torch thread is the
whole work), the wall figure what it took beside them. `--busy-core` runs a spinning process of its own
beside the measurement (the other core busy, as when anything else runs on a two-core machine) and
stops it after. `--write` stores the CPU figure in copilot_ray/measured_throughput.json
(`warm_start_s_per_phase.copilot`) with the command that measured it and both figures. A measurement,
not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
THROUGHPUT_FILE = ROOT / "copilot_ray" / "measured_throughput.json"


def seconds_per_phase(phases: int, layout: str) -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process) per warm-start phase."""
    import numpy as np
    import torch

    from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
    from copilot_ray.envs import make
    from copilot_ray.registry import RunContext

    torch.set_num_threads(1)  # train's main process (train.checked_run: num_cpus_for_main_process=1)
    run = RunContext("maze-point", {"layout": layout}, seed=0, num_cpus_for_main_process=1)
    config = CoPilotConfig.from_settings({"planner_warm_start": phases}, run)
    env = make("maze-point", layout=layout).unwrapped
    rng = np.random.default_rng(0)
    curriculum = config.make_curriculum(
        env, env.tasks("train"), env.tasks("test")[0], lambda layer: 0.1, rng, 0
    )
    wall, cpu = time.perf_counter(), time.process_time()
    curriculum.prepare(1, rng)
    return (time.perf_counter() - wall) / phases, (time.process_time() - cpu) / phases


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--phases", type=int, default=200)
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--busy-core", action="store_true", help="a spinning process beside the measurement")
    p.add_argument("--write", action="store_true", help="store the figure in measured_throughput.json")
    args = p.parse_args(argv)
    if args.phases < 1:
        raise SystemExit(f"--phases {args.phases!r} is invalid: must be an integer >= 1")
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.busy_core else None
    try:
        wall, cpu = seconds_per_phase(args.phases, args.layout)
    finally:
        if busy is not None:
            busy.terminate()
            busy.wait()
    beside = "a spinning process of its own beside it" if args.busy_core else "nothing of its own beside it"
    load = os.getloadavg()[0]
    figures = f"{wall:.3f} s wall, {cpu:.3f} s of CPU per phase"
    print(
        f"planner warm start on maze-point {args.layout}, one torch thread, {args.phases} phases: {figures} "
        f"({beside}; load average {load:.1f} at the end); 1000 phases: {1000 * wall:.0f} s wall, "
        f"{1000 * cpu:.0f} s with a core of its own"
    )
    if args.write:
        data = json.loads(THROUGHPUT_FILE.read_text())
        data.setdefault("warm_start_s_per_phase", {})["copilot"] = round(cpu, 3)
        command = " ".join(["benchmarks/warm_start.py", *(argv if argv is not None else sys.argv[1:])])
        data.setdefault("sources", {})["copilot.warm_start_s_per_phase"] = (
            f"{command} at commit {_commit()} on {time.strftime('%Y-%m-%d')}: the CPU seconds per phase "
            f"(a core of its own), one torch thread, {beside}; it ran {figures} at load average {load:.1f}"
        )
        THROUGHPUT_FILE.write_text(json.dumps(data, indent=2) + "\n")
        print(f"written to {THROUGHPUT_FILE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
