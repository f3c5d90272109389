"""Throughput of real sweep trials: env steps/s, SAC updates/s, where the wall time goes, trials per hour.

    PYTHONPATH=. python benchmarks/throughput.py [--algorithms copilot sac] [--concurrent 1 2]
        [--env-steps 40000] [--eval-every 10000] [--budget 200000] [--layout four-rooms] [--write]

For each algorithm and each N of `--concurrent`, one sweep of N trials (seeds 0..N-1) runs side by side
on this machine's Ray, each trial given cores // N CPUs (torch's threads follow them), on maze-point
`--layout` with the fair comparison's evaluation (100 validation + 100 test tasks every `--eval-every`
env steps, 10k as in sweeps/fair_maze.yaml),
until `--env-steps`. Everything is read back from the sweep's MLflow store, per iteration: env steps,
wall time (Tune's), and the phases the algorithm times (`copilot/time/*`: the traversal `agent_s`, of
which `agent_updates_s` are SAC's gradient steps, the planner, the cost model, evaluation). The rest of
an iteration's wall time is Ray, the Tune callback and logging ("other"). The first iteration (Ray and
the trial starting) is left out of the rates.

Prints per (algorithm, N): env steps/s per trial and in aggregate, SAC updates/s, the phase shares and
trials per hour at `--budget` env steps. `--write` stores the env steps/s of N = 1 and 2 in
copilot_ray/measured_throughput.json, which `python -m copilot_ray.sweep --check` turns into wall-time
estimates. Run it on an otherwise idle machine: another job on the cores halves every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
THROUGHPUT_FILE = ROOT / "copilot_ray" / "measured_throughput.json"
PHASES = ("agent_s", "agent_updates_s", "planner_s", "cost_model_s", "eval_s")


def _spec(algorithm: str, n: int, args, cpus: int, store: Path) -> dict:
    config = {"eval_every_env_steps": args.eval_every, "eval_num_tasks": 100}
    return {
        "name": f"throughput_{algorithm}_n{n}",
        "experiment": "throughput",
        "env": {"id": "maze-point", "config": {"layout": args.layout}},
        "algorithm": algorithm,
        "config": config,
        "seeds": list(range(n)),
        "stop": {"env_steps": args.env_steps, "min_evaluations": 1},
        "resources": {"max_concurrent_trials": n, "num_env_runners": 0, "cpus_per_trial": cpus},
        # Tune's folders beside the store, in the benchmark's temp dir: a rerun starts fresh.
        "tracking": {"uri": f"sqlite:///{store}", "storage": str(store.parent / "results")},
    }


def _histories(client, run_id: str, names) -> dict[str, dict[int, float]]:
    """metric -> {training iteration: value} (MLflow's step is env steps; timestamps order them)."""
    out = {}
    for name in names:
        rows = sorted(client.get_metric_history(run_id, name), key=lambda m: (m.step, m.timestamp))
        out[name] = [m.value for m in rows]
    return out


def measure(algorithm: str, n: int, args, cores: int, tmp: Path) -> dict:
    from mlflow.tracking import MlflowClient

    from copilot_ray import keys
    from copilot_ray.sweep import run_sweep
    from copilot_ray.sweep_spec import load_spec

    store = tmp / f"{algorithm}_n{n}.db"
    path = tmp / f"{algorithm}_n{n}.yaml"
    cpus = max(1, cores // n)
    path.write_text(yaml.safe_dump(_spec(algorithm, n, args, cpus, store)))
    t0 = time.perf_counter()
    outcome = run_sweep(load_spec(path))
    sweep_wall = time.perf_counter() - t0
    client = MlflowClient(f"sqlite:///{store}")
    runs = [
        r
        for e in client.search_experiments()
        for r in client.search_runs([e.experiment_id])
        if r.data.tags.get(keys.ROLE_TAG) == keys.ROLE_TRIAL
    ]
    names = (
        keys.ENV_STEPS,
        keys.TIME_TOTAL_S,
        keys.AGENT_SAC_UPDATES,
        *(keys.TIME_PREFIX + p for p in PHASES),
    )
    steps_s, updates_s, shares = [], [], {p: [] for p in (*PHASES, "other")}
    for run in runs:
        h = _histories(client, run.info.run_id, names)
        steps, wall = h[keys.ENV_STEPS], h[keys.TIME_TOTAL_S]
        if len(steps) < 3:
            continue
        d_steps = steps[-1] - steps[0]
        d_wall = wall[-1] - wall[0]
        steps_s.append(d_steps / d_wall)
        updates = h[keys.AGENT_SAC_UPDATES][1:]
        updates_s.append(sum(updates) / d_wall if updates else float("nan"))
        spent = {p: sum(h[keys.TIME_PREFIX + p][1:]) for p in PHASES}
        for p in PHASES:
            # agent_updates_s is inside agent_s: shown as its own share, taken out of agent_s's.
            share = spent[p] - (spent["agent_updates_s"] if p == "agent_s" else 0.0)
            shares[p].append(share / d_wall)
        outside = spent["agent_s"] + spent["planner_s"] + spent["cost_model_s"] + spent["eval_s"]
        shares["other"].append(max(0.0, d_wall - outside) / d_wall)
    if not steps_s:
        raise SystemExit(
            f"{algorithm} N={n}: no trial logged 3 iterations (status {outcome.status}); raise --env-steps"
        )
    per_trial = statistics.mean(steps_s)
    return {
        "algorithm": algorithm,
        "n": n,
        "cpus_per_trial": cpus,
        "trials": len(steps_s),
        "env_steps_per_s": per_trial,
        "aggregate_env_steps_per_s": per_trial * len(steps_s),
        "sac_updates_per_s": statistics.mean(updates_s),
        "shares": {p: statistics.mean(v) for p, v in shares.items()},
        "trials_per_hour": per_trial * len(steps_s) * 3600 / args.budget,
        "sweep_wall_s": sweep_wall,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algorithms", nargs="+", default=["copilot", "sac"])
    parser.add_argument("--concurrent", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--env-steps", type=int, default=40000, help="per trial")
    parser.add_argument("--eval-every", type=int, default=10000, help="env steps between evaluations")
    parser.add_argument("--budget", type=int, default=200000, help="env steps per trial for trials/hour")
    parser.add_argument("--layout", default="four-rooms")
    parser.add_argument("--write", action="store_true", help="store N = 1 and 2 in measured_throughput.json")
    args = parser.parse_args()
    bad = [n for n in args.concurrent if n < 1]
    if bad or args.env_steps < 1000 or args.budget < 1:
        raise SystemExit(
            f"error: --concurrent {bad or args.concurrent} / --env-steps {args.env_steps}: "
            "N >= 1, env steps >= 1000"
        )
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    import ray

    cores = os.cpu_count() or 1
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        ray.init(num_cpus=cores, include_dashboard=False, log_to_driver=False)
        try:
            for algorithm in args.algorithms:
                for n in args.concurrent:
                    if n > cores:
                        print(f"skipped {algorithm} N={n}: {cores} cores")
                        continue
                    rows.append(measure(algorithm, n, args, cores, Path(tmp)))
        finally:
            ray.shutdown()
    print(f"command: PYTHONPATH=. python benchmarks/throughput.py {shlex.join(sys.argv[1:])}")
    print(
        f"machine: {cores} cores, no GPU used; maze-point {args.layout}; trials/hour at {args.budget:,} env steps"
    )
    head = ("algorithm", "N", "CPUs/trial", "env steps/s", "aggregate", "updates/s", "trials/h")
    print("  ".join(f"{h:>11}" for h in head) + "  shares: " + " ".join(f"{p}" for p in (*PHASES, "other")))
    for r in rows:
        cells = (
            r["algorithm"],
            r["n"],
            r["cpus_per_trial"],
            f"{r['env_steps_per_s']:.0f}",
            f"{r['aggregate_env_steps_per_s']:.0f}",
            f"{r['sac_updates_per_s']:.0f}",
            f"{r['trials_per_hour']:.2f}",
        )
        shares = " ".join(f"{100 * r['shares'][p]:.0f}%" for p in (*PHASES, "other"))
        print("  ".join(f"{c!s:>11}" for c in cells) + "  " + shares)
    if args.write:
        data = json.loads(THROUGHPUT_FILE.read_text())
        for r in rows:
            slot = {1: "lone", 2: "side_by_side"}.get(r["n"])
            if slot:
                data["env_steps_per_s"].setdefault(r["algorithm"], {})[slot] = round(r["env_steps_per_s"])
        data["source"] = (
            f"benchmarks/throughput.py {shlex.join(sys.argv[1:])} on {time.strftime('%Y-%m-%d')}; "
            "refresh with benchmarks/throughput.py --write"
        )
        data["machine"] = f"{cores}-core CPU, no GPU"
        THROUGHPUT_FILE.write_text(json.dumps(data, indent=2) + "\n")
        print(f"wrote {THROUGHPUT_FILE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
