"""Sample efficiency on the maze: success on the 100 held-out test tasks against environment steps.

Runs CO-PILOT under one or more presets (readings of the paper: `default`, the measured defaults;
`paper_literal`; `plain_sac`, the same SAC learner with no planner) on the same env-step budget, one
process, no Tune. Every iteration prints one line with the test success and the diagnostics that say
why a run does (not) learn; rows.json is rewritten after every iteration (a killed run keeps them) and
a PNG and a table are written at the end. A measurement, not a test.

    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --env-steps 80000
    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --presets default --set after_failure=continue
    PYTHONPATH=. .venv/bin/python benchmarks/maze_learning.py --presets paper_literal plain_sac --seeds 0 1

`--set KEY=VALUE` takes the keys of a sweep spec's `config` (copilot_ray/spec.py COPILOT_KNOBS, e.g.
`planner.std_final=0.015`, `initial_alpha=1e-3`); values are read as YAML. The multi-seed evidence
for the README comes from `sweeps/maze_learning.yaml` through `analysis.report`; this script is for
quick probes of one knob.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("RAY_AUTH_MODE", "disabled")

# Printed per iteration: (label, metric key under copilot/, format); <K> is the tree depth.
COLUMNS = (
    ("planned", "eval/success_planned", "{:.2f}"),
    ("direct", "eval/success_direct", "{:.2f}"),
    ("reached", "eval/reached_planned", "{:.2f}"),
    ("subgoals", "eval/subgoals_reached_planned", "{:.2f}"),
    ("plan free", "eval/planned_collision_free", "{:.2f}"),
    ("sub-task K", "agent/subtask_success_layer_<K>", "{:.2f}"),
    ("after failed", "diag/success_after_failed", "{:.2f}"),
    ("unreachable K", "diag/segment_unreachable_layer_<K>", "{:.2f}"),
    ("Q", "diag/q_mean", "{:.2f}"),
)


def parse_sets(items: list[str]) -> dict:
    from copilot_ray.spec import COPILOT_KNOBS, load_yaml_value

    out = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item!r}: use KEY=VALUE")
        if key not in COPILOT_KNOBS:
            raise SystemExit(f"--set {key}: unknown key; known: {', '.join(sorted(COPILOT_KNOBS))}")
        value = load_yaml_value(text)
        if problem := COPILOT_KNOBS[key].problem(key, value):
            raise SystemExit(f"--set {key}={text}: {problem}")
        out[key] = value
    return out


def build(preset: str, args, seed: int, sets: dict):
    from copilot_ray.algorithms.copilot import CoPilotConfig
    from copilot_ray.spec import COPILOT_KNOBS

    config = (
        CoPilotConfig()
        .environment("maze-point", env_config={"layout": args.layout})
        .env_runners(num_env_runners=0)
        .resources(num_cpus_for_main_process=1)
        .debugging(seed=seed)
        .copilot(preset=preset)
        .copilot(task_batch_size=args.task_batch_size, eval_num_tasks=100, eval_tree_tasks=0)
    )
    copilot, nested, training = {}, {"planner": {}, "cost_model": {}}, {}
    for key, value in sets.items():
        target = COPILOT_KNOBS[key].target
        if target in nested:
            nested[target][key.split(".", 1)[1]] = value
        elif target == "training":
            training[key] = value
        else:
            copilot[key] = value
    config.copilot(**copilot, **{k: v for k, v in nested.items() if v})
    if training:
        config.training(**training)
    return config.build_algo()


def run_one(preset: str, args, seed: int, sets: dict, rows_path: Path, done: list[dict]) -> list[dict]:
    algo = build(preset, args, seed, sets)
    depth = algo.config.tree_depth
    rows = []
    started = time.time()
    try:
        while True:
            result = algo.train()
            steps = int(result["env_runners"]["num_env_steps_sampled_lifetime"])
            flat = _flatten(result.get("copilot", {}))
            row = {
                "preset": preset,
                "seed": seed,
                "iteration": result["training_iteration"],
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
    axes[0].set_ylabel("success on 100 test tasks")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--layout", default="four-rooms")
    p.add_argument("--env-steps", type=int, default=60_000, help="budget per run")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--presets", nargs="+", default=["default", "plain_sac"])
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--task-batch-size", type=int, default=2, help="tasks traversed per iteration")
    p.add_argument("--out", default="results/benchmarks/maze_learning")
    args = p.parse_args(argv)
    from copilot_ray.algorithms.copilot.readings import PRESETS

    unknown = [name for name in args.presets if name not in PRESETS]
    if unknown:
        raise SystemExit(f"--presets {unknown[0]!r}: unknown; known: {', '.join(PRESETS)}")
    sets = parse_sets(args.sets)

    import ray

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
    print("\npreset         seed  env_steps  final planned  final direct  best planned  wall_s")
    for preset, seed in sorted({(r["preset"], r["seed"]) for r in rows}):
        pts = [r for r in rows if r["preset"] == preset and r["seed"] == seed]
        last = pts[-1]
        best = max(r["planned"] for r in pts)
        print(
            f"{preset:13s}  {seed:4d}  {last['env_steps']:9d}  {last['planned']:13.2f}  "
            f"{last['direct']:12.2f}  {best:12.2f}  {last['wall_s']:6.0f}"
        )
    print(f"\nwrote {out / 'success_vs_env_steps.png'} and {out / 'rows.json'}")


if __name__ == "__main__":
    main()
