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
copilot_ray/measured_throughput.json (each figure with the command that measured it), which `python -m copilot_ray.sweep --check` turns into wall-time
estimates. Run it on an otherwise idle machine: another job on the cores halves every figure.

    PYTHONPATH=. python benchmarks/throughput.py --from-store URI [--experiment NAME] [--sweeps NAME ...]
        --concurrent N
        [--algorithms all] [--write]

runs nothing: it reads the same figures from a sweep that already ran (every finished trial run of the
experiment, per algorithm, N of them at a time), e.g. a comparison's stage 1 at its real evaluation
cadence, and `--write` stores them as N's slot.
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
    rows = rates(client, _trial_runs(client))
    if not rows:
        raise SystemExit(
            f"{algorithm} N={n}: no trial logged 3 iterations (status {outcome.status}); raise --env-steps"
        )
    row = rows[algorithm]
    return {
        **row,
        "n": n,
        "cpus_per_trial": cpus,
        "aggregate_env_steps_per_s": row["env_steps_per_s"] * n,
        "trials_per_hour": row["env_steps_per_s"] * n * 3600 / args.budget,
        "sweep_wall_s": sweep_wall,
    }


def _trial_runs(
    client, experiment: str | None = None, finished_only: bool = False, sweeps: list[str] | None = None
) -> list:
    from copilot_ray import keys

    experiments = client.search_experiments()
    return [
        r
        for e in experiments
        if experiment is None or e.name == experiment
        for r in client.search_runs([e.experiment_id], max_results=5000)
        if r.data.tags.get(keys.ROLE_TAG) == keys.ROLE_TRIAL
        and (not finished_only or r.info.status == "FINISHED")
        and (not sweeps or r.data.tags.get(keys.SWEEP_TAG) in sweeps)
    ]


def phase_shares(spent: dict[str, float], wall: float) -> dict[str, float]:
    """Each phase's share of `wall` seconds from the seconds `spent` in it (PHASES), and "other": the rest
    (Ray, the Tune callback, logging). agent_updates_s is inside agent_s: its own share, taken out of
    agent_s's."""
    shares = {p: (spent[p] - (spent["agent_updates_s"] if p == "agent_s" else 0.0)) / wall for p in PHASES}
    inside = spent["agent_s"] + spent["planner_s"] + spent["cost_model_s"] + spent["eval_s"]
    shares["other"] = max(0.0, wall - inside) / wall
    return shares


def rates(client, runs) -> dict[str, dict]:
    """Per algorithm (the runs' tag): env steps/s per trial (mean over runs), SAC updates/s and the phase
    shares, from each run's iterations after its first (Ray and the trial starting, CO-PILOT's planner
    warm start)."""
    from copilot_ray import keys

    names = (
        keys.ENV_STEPS,
        keys.TIME_TOTAL_S,
        keys.AGENT_SAC_UPDATES,
        *(keys.TIME_PREFIX + p for p in PHASES),
    )
    by_algorithm: dict[str, list[tuple[float, float, dict]]] = {}
    for run in runs:
        h = _histories(client, run.info.run_id, names)
        steps, wall = h[keys.ENV_STEPS], h[keys.TIME_TOTAL_S]
        if len(steps) < 3 or len(wall) != len(steps):
            continue
        d_steps = steps[-1] - steps[0]
        d_wall = wall[-1] - wall[0]
        updates = h[keys.AGENT_SAC_UPDATES][1:]
        spent = {p: sum(h[keys.TIME_PREFIX + p][1:]) for p in PHASES}
        rate = (
            d_steps / d_wall,
            sum(updates) / d_wall if updates else float("nan"),
            phase_shares(spent, d_wall),
        )
        by_algorithm.setdefault(run.data.tags.get(keys.ALGORITHM_TAG, "?"), []).append(rate)
    out = {}
    for algorithm, measured in by_algorithm.items():
        per_trial = statistics.mean(m[0] for m in measured)
        out[algorithm] = {
            "algorithm": algorithm,
            "trials": len(measured),
            "env_steps_per_s": per_trial,
            "sac_updates_per_s": statistics.mean(m[1] for m in measured),
            "shares": {p: statistics.mean(m[2][p] for m in measured) for p in (*PHASES, "other")},
        }
    return out


def run_and_measure(args, cores: int) -> list[dict]:
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    import ray

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
    return rows


def portable(argv: list[str]) -> list[str]:
    """The command as `--check` shows it on any machine: a store named by its file, not by the absolute
    path of the worktree it was measured in."""
    return [Path(a.removeprefix("sqlite:///")).name if a.startswith("sqlite:///") else a for a in argv]


def from_store(args, cores: int) -> list[dict]:
    """The rates of a sweep that already ran (e.g. a comparison's parts, N = --concurrent side by side):
    every FINISHED trial run of `--experiment` (or of every experiment) in the store, per algorithm."""
    from mlflow.tracking import MlflowClient

    from copilot_ray.store import missing_sqlite_file

    if (missing := missing_sqlite_file(args.from_store)) is not None:
        raise SystemExit(f"error: --from-store {args.from_store}: {missing} does not exist")
    client = MlflowClient(args.from_store)
    runs = _trial_runs(client, args.experiment, finished_only=True, sweeps=args.sweeps)
    found = rates(client, runs)
    if not found:
        raise SystemExit(
            f"error: --from-store {args.from_store}: no finished trial run"
            + (f" of experiment {args.experiment!r}" if args.experiment else "")
            + (f" in sweeps {args.sweeps}" if args.sweeps else "")
            + " logged 3 iterations"
        )
    (n,) = args.concurrent
    return [
        {
            **row,
            "n": n,
            "cpus_per_trial": max(1, cores // n),
            "aggregate_env_steps_per_s": row["env_steps_per_s"] * n,
            "trials_per_hour": row["env_steps_per_s"] * n * 3600 / args.budget,
        }
        for algorithm, row in sorted(found.items())
        if algorithm in args.algorithms or args.algorithms == ["all"]
    ]


def _commits(args) -> list[str]:
    from mlflow.tracking import MlflowClient

    from copilot_ray import keys

    runs = _trial_runs(MlflowClient(args.from_store), args.experiment, finished_only=True, sweeps=args.sweeps)
    return sorted({r.data.tags.get(keys.GIT_COMMIT_TAG, "?")[:7] for r in runs})


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--algorithms", nargs="+", default=["copilot", "sac"], help="('all' with --from-store)"
    )
    parser.add_argument("--concurrent", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--env-steps", type=int, default=40000, help="per trial")
    parser.add_argument("--eval-every", type=int, default=10000, help="env steps between evaluations")
    parser.add_argument("--budget", type=int, default=200000, help="env steps per trial for trials/hour")
    parser.add_argument("--layout", default="four-rooms")
    parser.add_argument(
        "--from-store",
        metavar="URI",
        help="run nothing: read the rates of a sweep that ran (its finished trials, --concurrent N at a time)",
    )
    parser.add_argument("--experiment", help="with --from-store: only this MLflow experiment's runs")
    parser.add_argument(
        "--sweeps", nargs="+", help="with --from-store: only these sweeps' runs (their names)"
    )
    parser.add_argument("--write", action="store_true", help="store N = 1 and 2 in measured_throughput.json")
    return parser.parse_args(argv)


def main() -> None:
    args = parse_args()
    bad = [n for n in args.concurrent if n < 1]
    if bad or args.env_steps < 1000 or args.budget < 1:
        raise SystemExit(
            f"error: --concurrent {bad or args.concurrent} / --env-steps {args.env_steps}: "
            "N >= 1, env steps >= 1000"
        )
    if args.from_store is not None and len(args.concurrent) != 1:
        raise SystemExit(
            f"error: --from-store needs one --concurrent N (how many ran at a time), not {args.concurrent}"
        )
    if (args.experiment is not None or args.sweeps) and args.from_store is None:
        raise SystemExit("error: --experiment and --sweeps read a store: give --from-store URI")
    cores = os.cpu_count() or 1
    if args.from_store is not None:
        rows = from_store(args, cores)
    else:
        rows = run_and_measure(args, cores)
    print(f"command: PYTHONPATH=. python benchmarks/throughput.py {shlex.join(sys.argv[1:])}")
    print(
        f"machine: {cores} cores, no GPU used; "
        + (f"store {args.from_store}" if args.from_store else f"maze-point {args.layout}")
        + f"; trials/hour at {args.budget:,} env steps"
    )
    head = ("algorithm", "N", "CPUs/trial", "env steps/s", "aggregate", "updates/s", "trials/h", "ms/step")
    print(
        "  ".join(f"{h:>11}" for h in head)
        + "  shares (ms per env step): "
        + " ".join(f"{p}" for p in (*PHASES, "other"))
    )
    for r in rows:
        cells = (
            r["algorithm"],
            r["n"],
            r["cpus_per_trial"],
            f"{r['env_steps_per_s']:.0f}",
            f"{r['aggregate_env_steps_per_s']:.0f}",
            f"{r['sac_updates_per_s']:.0f}",
            f"{r['trials_per_hour']:.2f}",
            f"{1000 / r['env_steps_per_s']:.2f}",
        )
        # Each phase's share of the wall time and its cost per env step (ms).
        ms = 1000 / r["env_steps_per_s"]
        shares = " ".join(
            f"{100 * r['shares'][p]:.0f}% ({r['shares'][p] * ms:.2f})" for p in (*PHASES, "other")
        )
        print("  ".join(f"{c!s:>11}" for c in cells) + "  " + shares)
    if args.write:
        data = json.loads(THROUGHPUT_FILE.read_text())
        source = (
            f"benchmarks/throughput.py {shlex.join(portable(sys.argv[1:]))} on {time.strftime('%Y-%m-%d')}"
        )
        if args.from_store:
            source += f" (its runs' commits: {', '.join(_commits(args))})"
        for r in rows:
            slot = {1: "lone", 2: "side_by_side"}.get(r["n"])
            if slot:
                data["env_steps_per_s"].setdefault(r["algorithm"], {})[slot] = round(r["env_steps_per_s"])
                data.setdefault("sources", {})[f"{r['algorithm']}.{slot}"] = source
        data["machine"] = f"{cores}-core CPU, no GPU"
        THROUGHPUT_FILE.write_text(json.dumps(data, indent=2) + "\n")
        print(f"wrote {THROUGHPUT_FILE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
