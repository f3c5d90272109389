"""Sample efficiency on the maze: success on the 100 held-out test tasks against environment steps.

Compares CO-PILOT with plain goal-conditioned SAC (the same learner, no planner: tree_depth 0, one
episode of 2^K * tau_max steps per task, i.e. the step budget of one finest traversal) on the same
env-step budget. Prints a table and writes a PNG; this is a measurement, not a test.

    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --env-steps 100000
    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --seeds 0 1 2 --methods copilot sac

The paper's budget is 1.8 M env steps per run; at about 100 SAC updates/s on two CPU cores (one
update per env step) that is about 5 hours per run, so the default here is much smaller.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("RAY_AUTH_MODE", "disabled")


def build(method: str, args, seed: int):
    from copilot_ray.algorithms.copilot import CoPilotConfig

    config = (
        CoPilotConfig()
        .environment("maze-point", env_config={"layout": args.layout})
        .env_runners(num_env_runners=0)
        .debugging(seed=seed)
        .copilot(eval_num_tasks=100, updates_per_env_step=args.updates_per_env_step)
    )
    if method == "copilot":
        config.copilot(
            tree_depth=args.tree_depth,
            repetitions=args.repetitions,
            task_batch_size=args.task_batch_size,
            tau_max=args.tau_max,
        )
    elif method == "sac":
        config.copilot(
            tree_depth=0,
            repetitions=1,
            task_batch_size=args.task_batch_size,
            tau_max=args.tau_max * 2**args.tree_depth,
        )
    else:
        raise SystemExit(f"unknown method {method!r}: use copilot or sac")
    return config.build_algo()


def run_one(method: str, args, seed: int, rows_path: Path, done: list[dict]) -> list[dict]:
    algo = build(method, args, seed)
    rows = []
    started = time.time()
    try:
        while True:
            result = algo.train()
            steps = int(result["env_runners"]["num_env_steps_sampled_lifetime"])
            ev = result.get("copilot", {}).get("eval", {})
            row = {
                "method": method,
                "seed": seed,
                "iteration": result["training_iteration"],
                "env_steps": steps,
                "success_planned": float(ev.get("success_planned", float("nan"))),
                "success_direct": float(ev.get("success_direct", float("nan"))),
                "wall_s": time.time() - started,
                "planning_share": float(result["copilot"]["time"]["planning_share"]),
            }
            rows.append(row)
            # Written every iteration: a killed benchmark keeps what it measured.
            rows_path.write_text(json.dumps(done + rows, indent=1))
            print(
                f"{method:8s} seed {seed}  iter {row['iteration']:3d}  env_steps {steps:8d}  "
                f"planned {row['success_planned']:.2f}  direct {row['success_direct']:.2f}  "
                f"wall {row['wall_s']:7.1f}s  planning share {row['planning_share']:.1%}",
                flush=True,
            )
            if steps >= args.env_steps:
                break
    finally:
        algo.stop()
    return rows


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, key in zip(axes, ("success_planned", "success_direct"), strict=True):
        for method, seed in sorted({(r["method"], r["seed"]) for r in rows}):
            pts = [r for r in rows if r["method"] == method and r["seed"] == seed]
            ax.plot(
                [r["env_steps"] for r in pts], [r[key] for r in pts], marker="o", label=f"{method} s{seed}"
            )
        ax.set_title(key.replace("_", " "))
        ax.set_xlabel("environment steps")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success on 100 test tasks")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--env-steps", type=int, default=60_000, help="budget per run")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--methods", nargs="+", default=["copilot", "sac"])
    p.add_argument("--tree-depth", type=int, default=5)
    p.add_argument("--repetitions", type=int, default=5)
    p.add_argument("--task-batch-size", type=int, default=4, help="tasks per iteration (paper: 30)")
    p.add_argument("--tau-max", type=int, default=25)
    p.add_argument("--updates-per-env-step", type=float, default=1.0)
    p.add_argument("--out", default="results/benchmarks/maze_learning")
    args = p.parse_args(argv)

    import ray

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    rows: list[dict] = []
    try:
        for seed in args.seeds:
            for method in args.methods:
                rows += run_one(method, args, seed, out / "rows.json", rows)
    finally:
        ray.shutdown()

    plot(rows, out / "success_vs_env_steps.png")
    print("\nmethod    seed  env_steps  final planned  final direct  best planned  wall_s")
    for method, seed in sorted({(r["method"], r["seed"]) for r in rows}):
        pts = [r for r in rows if r["method"] == method and r["seed"] == seed]
        last = pts[-1]
        best = max(r["success_planned"] for r in pts)
        print(
            f"{method:8s}  {seed:4d}  {last['env_steps']:9d}  {last['success_planned']:13.2f}  "
            f"{last['success_direct']:12.2f}  {best:12.2f}  {last['wall_s']:6.0f}"
        )
    print(f"\nwrote {out / 'success_vs_env_steps.png'} and {out / 'rows.json'}")


if __name__ == "__main__":
    main()
