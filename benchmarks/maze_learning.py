"""A probe of CO-PILOT's sample efficiency on the maze: success on the 100 VALIDATION tasks against
environment steps (a probe chooses; the test tasks are for reports).

Runs CO-PILOT under one or more presets (readings of the paper: `default`, the measured defaults;
`paper_literal`) on the same env-step budget, one process, no Tune. Every iteration prints one line with the test success and the diagnostics that say
why a run does (not) learn, and inside an iteration a line every few seconds (warm-start phases, env
steps, SAC updates, evaluations: `copilot_ray.heartbeat.show_progress`; `--no-progress` for none);
rows.json is rewritten after every iteration (a killed run keeps them) and a PNG and a table are written
at the end. A measurement, not a test.

    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --env-steps 80000
    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --presets default --set after_failure=continue
    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --presets default paper_literal --seeds 0 1

`--set KEY=VALUE` takes the keys of a sweep spec's `config` (the settings of copilot_ray/algorithms/copilot/settings.py, e.g.
`planner.std_final=0.015`, `initial_alpha=1e-3`); values are read as YAML. The multi-seed evidence
for the README comes from `sweeps/fair_maze.yaml` through `analysis.report`; this script is for quick
probes of one knob.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from copilot_ray.keys import (
    AGENT_SUBTASK_SUCCESS_LAYER,
    COPILOT_PREFIX,
    DIAG_Q_MEAN,
    DIAG_SEGMENT_UNREACHABLE_LAYER,
    DIAG_SUCCESS_AFTER_FAILED,
    ENV_STEPS,
    EVAL_SUCCESS_AUC,
    PLANNED_COLLISION_FREE,
    REACHED_PLANNED,
    SUBGOALS_REACHED_PLANNED,
    SUCCESS_DIRECT,
    SUCCESS_PLANNED,
    TRAINING_ITERATION,
    result_value,
    validation_key,
)

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

# Printed per iteration: (label, metric key, format); <K> is the tree depth. Evaluation figures are
# the validation tasks'.
COLUMNS = (
    ("planned", validation_key(SUCCESS_PLANNED), "{:.2f}"),
    ("auc", validation_key(EVAL_SUCCESS_AUC), "{:.3f}"),
    ("direct", validation_key(SUCCESS_DIRECT), "{:.2f}"),
    ("reached", validation_key(REACHED_PLANNED), "{:.2f}"),
    ("subgoals", validation_key(SUBGOALS_REACHED_PLANNED), "{:.2f}"),
    ("plan free", validation_key(PLANNED_COLLISION_FREE), "{:.2f}"),
    ("sub-task K", AGENT_SUBTASK_SUCCESS_LAYER + "<K>", "{:.2f}"),
    ("after failed", DIAG_SUCCESS_AFTER_FAILED, "{:.2f}"),
    ("unreachable K", DIAG_SEGMENT_UNREACHABLE_LAYER + "<K>", "{:.2f}"),
    ("Q", DIAG_Q_MEAN, "{:.2f}"),
)


def parse_sets(items: list[str]) -> dict:
    """`--set KEY=VALUE` items as setting values (YAML values, as in a spec); exits naming a bad one."""
    from copilot_ray.algorithms.copilot.settings import SETTINGS
    from copilot_ray.settings import problems
    from copilot_ray.sweep_spec import load_yaml_value

    out = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item!r}: use KEY=VALUE")
        out[key] = load_yaml_value(text)
    for key, value, why in problems(SETTINGS, out):
        known = f"; known: {', '.join(sorted(SETTINGS))}" if why == "unknown key" else ""
        raise SystemExit(f"--set {key}={value!r}: {why}{known}")
    return out


def build(preset: str, args, seed: int, sets: dict):
    from copilot_ray.algorithms.copilot.algorithm import CoPilotConfig
    from copilot_ray.registry import RunContext

    run = RunContext("maze-point", {"layout": args.layout}, seed=seed, num_cpus_for_main_process=1)
    values = {
        "preset": preset,
        "task_batch_size": args.task_batch_size,
        "eval_num_tasks": 100,
        "eval_tree_tasks": 0,
        **sets,
    }
    return CoPilotConfig.from_settings(values, run).build_algo()


def run_one(preset: str, args, seed: int, sets: dict, rows_path: Path, done: list[dict]) -> list[dict]:
    algo = build(preset, args, seed, sets)
    depth = algo.config.tree_depth
    rows = []
    started = time.time()
    try:
        while True:
            result = algo.train()
            steps = int(result_value(result, ENV_STEPS))
            flat = _flatten(result.get("copilot", {}), COPILOT_PREFIX)
            row = {
                "preset": preset,
                "seed": seed,
                "iteration": result[TRAINING_ITERATION],
                "env_steps": steps,
            }
            row["wall_s"] = time.time() - started
            for label, key, _ in COLUMNS:
                row[label] = flat.get(key.replace("<K>", str(depth)), float("nan"))
            rows.append(row)
            rows_path.write_text(json.dumps(done + rows, indent=1))  # a killed run keeps its rows
            cells = "  ".join(f"{label} {fmt.format(row[label])}" for label, _, fmt in COLUMNS)
            print(
                f"{preset:13s} s{seed} it {row['iteration']:3d} steps {steps:7d}  {cells}  {row['wall_s']:6.0f}s",
                flush=True,
            )
            if steps >= args.env_steps:
                break
    finally:
        algo.stop()
    return rows


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}/"))
        else:
            out[f"{prefix}{k}"] = v
    return out


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, key in zip(axes, ("planned", "direct"), strict=True):
        for preset, seed in sorted({(r["preset"], r["seed"]) for r in rows}):
            pts = [r for r in rows if r["preset"] == preset and r["seed"] == seed]
            ax.plot(
                [r["env_steps"] for r in pts], [r[key] for r in pts], marker="o", label=f"{preset} s{seed}"
            )
        ax.set_title(f"success, {key}")
        ax.set_xlabel("environment steps")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success on 100 validation tasks")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--env-steps", type=int, default=60_000, help="budget per run")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--presets", nargs="+", default=["default"])
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--task-batch-size", type=int, default=2, help="tasks traversed per iteration")
    p.add_argument("--out", default="results/benchmarks/maze_learning")
    p.add_argument("--no-progress", action="store_true", help="no lines inside an iteration")
    args = p.parse_args(argv)
    from copilot_ray.algorithms.copilot.settings import PRESETS

    unknown = [name for name in args.presets if name not in PRESETS]
    if unknown:
        raise SystemExit(f"--presets {unknown[0]!r}: unknown; known: {', '.join(PRESETS)}")
    sets = parse_sets(args.sets)

    import ray

    from copilot_ray.heartbeat import show_progress

    if not args.no_progress:
        show_progress()  # the warm start alone is minutes without a line otherwise
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    rows: list[dict] = []
    try:
        for seed in args.seeds:
            for preset in args.presets:
                rows += run_one(preset, args, seed, sets, out / "rows.json", rows)
    finally:
        ray.shutdown()

    plot(rows, out / "success_vs_env_steps.png")
    print("\nvalidation tasks; AUC: area under the planned success curve / its env-step span")
    print("preset         seed  env_steps  final planned  final direct    AUC  wall_s")
    for preset, seed in sorted({(r["preset"], r["seed"]) for r in rows}):
        last = [r for r in rows if r["preset"] == preset and r["seed"] == seed][-1]
        print(
            f"{preset:13s}  {seed:4d}  {last['env_steps']:9d}  {last['planned']:13.2f}  "
            f"{last['direct']:12.2f}  {last['auc']:5.3f}  {last['wall_s']:6.0f}"
        )
    print(f"\nwrote {out / 'success_vs_env_steps.png'} and {out / 'rows.json'}")


if __name__ == "__main__":
    main()
