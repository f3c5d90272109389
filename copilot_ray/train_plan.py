"""`python -m copilot_ray.train ... --check`: what one run will do and how long it will take, said before
anything starts (no Ray, no RLlib, no file written).

The plan names the env, the settings that size the run (K, b, tau_max, the task batch, the warm start),
the budget, the most env steps an iteration can take and how far past the budget the last one can go
(the bound a stop or a resumed run keeps), the evaluations, the store and the checkpoint folder. The wall
time is the warm start's phases at a measured seconds-per-phase figure plus the env steps at the
measured rate of a lone run (`copilot_ray/measured_throughput.json`, read by the sweep's `--check` too:
`sweep_spec/estimate.py`); both were measured on maze-point four-rooms at the defaults, as the line says.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from copilot_ray.registry import get_algorithm
from copilot_ray.settings import effective
from copilot_ray.sweep_spec.estimate import (
    THROUGHPUT_FILE,
    WARM_START,
    duration_text,
    measured_rate,
    measured_warm_start_phase,
    run_estimate,
)


def format_train_plan(
    algorithm: str,
    env: str,
    layout: str | None,
    seed: int,
    values: dict[str, Any],
    budget: int,
    iterations: int | None,
    tracking: str | None,
    checkpoint: str,
) -> str:
    """The plan of one `train` run: `values` the settings given, `budget` and `iterations` its stops,
    `tracking` the MLflow store (None: no tracking), `checkpoint` the folder its checkpoint goes to."""
    entry = get_algorithm(algorithm)
    v = effective(entry.settings, values, entry.presets)
    est = run_estimate(entry, v, "the run", budget, iterations)
    depth, b, batch = int(v["tree_depth"]), int(v["repetitions"]), int(v["task_batch_size"])
    phases = int(v["planner_warm_start"])
    where = f"{env} ({layout})" if layout else env
    lines = [
        f"train --check: CO-PILOT on {where}, seed {seed}, preset {v.get('preset') or 'default'}; nothing "
        "started, nothing written",
        f"  settings: K={depth} (--tree-depth), b={b} (--repetitions), tau_max={v['tau_max']}, "
        f"{batch} tasks traversed per batch (--task-batch-size), "
        + (f"planner warm start {phases:,} phases" if phases else "no planner warm start")
        + " (--planner-warm-start)",
        f"  budget: {budget:,} env steps (--stop-env-steps)"
        + (f" or {iterations} iterations (--stop-iters), whichever comes first" if iterations else ""),
        f"  an iteration: <= {est.max_iteration_env_steps:,} env steps ({b} repetitions of <= "
        f"{est.max_env_steps_between_checks:,}); the last ends at the repetition that reaches the budget "
        f"(<= {est.max_env_steps_between_checks - 1:,} past it), and a stop (Ctrl-C, SIGTERM) at the end of "
        "a warm-start phase or a repetition, so a resumed run keeps these bounds",
        "  " + _evaluations(v, est),
        f"  MLflow: {tracking}" if tracking else "  MLflow: none (--no-tracking)",
        f"  checkpoint: {checkpoint} (at the end, and on Ctrl-C or SIGTERM; --resume continues from it; "
        "the planner's trees go there too)",
        _wall_time(algorithm, v, budget, iterations),
    ]
    return "\n".join(lines)


def _evaluations(v: dict[str, Any], est) -> str:
    tasks = f"{v['eval_num_tasks']} validation + {v['eval_num_tasks']} test tasks"
    cadence, interval = int(v["eval_every_env_steps"] or 0), int(v["eval_interval"] or 0)
    if cadence:
        when = f"at every {cadence:,} env steps (the end of the repetition past each point)"
    elif interval:
        when = "after every iteration" if interval == 1 else f"after every {interval} iterations"
    else:
        return "evaluations: none (eval_interval 0, eval_every_env_steps 0)"
    count = "" if est.min_evaluations is None else f"; >= {est.min_evaluations} in the run ({est.why})"
    return f"evaluations: {tasks} {when}{count}"


def expected_seconds(
    algorithm: str, values: dict[str, Any], budget: int, iterations: int | None
) -> float | None:
    """The wall seconds `--check` expects of a run of the settings `values` (after Ray's start and the
    build), or None without the measured figures."""
    entry = get_algorithm(algorithm)
    parts = _wall_parts(algorithm, effective(entry.settings, values, entry.presets), budget, iterations)
    return None if parts is None else sum(seconds for seconds, _ in parts)


def _wall_parts(
    algorithm: str, v: dict[str, Any], budget: int, iterations: int | None
) -> list[tuple[float, str]] | None:
    """(seconds, how) of the warm start (its phases at the measured seconds per phase) and of the env
    steps (at a lone run's measured rate), for the effective settings `v`; None without the figures."""
    phases = int(v["planner_warm_start"])
    steps = budget
    if iterations is not None:  # the iterations may end the run first
        steps = min(budget, iterations * int(get_algorithm(algorithm).max_iteration_env_steps(v)))
    rate = measured_rate(algorithm, 1)
    phase = measured_warm_start_phase(algorithm) if phases else (0.0, "")
    if rate is None or phase is None:
        return None
    parts = []
    if phases:
        warm_s = phases * phase[0]
        parts.append(
            (warm_s, f"the warm start's {phases:,} phases x {phase[0]:.2f} s = {duration_text(warm_s)}")
        )
    env_s = steps / rate[0]
    at_most = "at most " if steps < budget else ""
    parts.append(
        (env_s, f"{at_most}{steps:,} env steps at ~{rate[0]:.0f} env steps/s = {duration_text(env_s)}")
    )
    return parts


def _wall_time(algorithm: str, v: dict[str, Any], budget: int, iterations: int | None) -> str:
    parts = _wall_parts(algorithm, v, budget, iterations)
    if parts is None:
        return f"  wall time: not estimated (no measured figure for {algorithm} in {THROUGHPUT_FILE.name})"
    keys = [f"{algorithm}.{WARM_START}"] * (len(parts) > 1) + [f"{algorithm}.lone"]
    return (
        f"  wall time: about {duration_text(sum(s for s, _ in parts))} with a core of its own, after Ray's "
        "start and the build (~1 min): "
        + " + ".join(how for _, how in parts)
        + f"\n    (measured on maze-point four-rooms at the defaults, how: {THROUGHPUT_FILE.name}'s sources "
        + " and ".join(keys)
        + "; other envs and settings differ, and other work on the cores slows a run)"
    )


def checkpoint_folder(
    algorithm: str, given: str | None, results: Path, env: str, values: dict[str, Any], seed: int
) -> str:
    """Where the run's checkpoint goes: --checkpoint-dir, or a folder named after the run (train.run_name's
    pattern, the start time to come)."""
    if given:
        return given
    entry = get_algorithm(algorithm)
    v = effective(entry.settings, values, entry.presets)
    return f"{results}/{env}-K{v['tree_depth']}-b{v['repetitions']}-s{seed}-<start time>/"
