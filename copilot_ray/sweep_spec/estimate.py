"""What a sweep will cost and whether its trials will be evaluated: the numbers `--check` prints.

* Env steps per iteration: the most one iteration can take (every sub-task or episode to its step
  limit: the algorithm's `max_iteration_env_steps`), per configuration.
* Evaluations per trial: the fewest a trial gets before its env-step budget ends, from that bound (or,
  for an algorithm that ends an iteration at the repetition past an evaluation point, a repetition's) and
  the evaluation cadence (`eval_every_env_steps`, else `eval_interval` iterations). A plan in which a
  trial could end with fewer than `stop.min_evaluations` (default MIN_EVALUATIONS) is refused: its curve
  and its final figure would be one or two noisy points (or none).
* Wall time: trials x budget / a measured env-steps-per-second figure (`copilot_ray/
  measured_throughput.json`, written by `benchmarks/throughput.py --write`), in waves of
  `max_concurrent_trials`, plus each trial's planner warm start (CO-PILOT's phases before its first env
  step, at the file's seconds per phase): the rate is read after a trial's first iteration, so it
  leaves the warm start out. A spec whose trials hold a GPU (`resources.gpus_per_trial` > 0) reads the
  file's GPU figures (`env_steps_per_s_gpu`, from the GPU check `scripts/device_check.sh`) and is not
  estimated without one: a CPU figure would be wrong either way.
* `train --check` (copilot_ray/train_plan.py) reads the same file: a lone run's rate and the planner warm
  start's seconds per phase (`measured_warm_start_phase`), with one run's estimate (`run_estimate`).

Standard library only (no Ray): `--check` and the spec's validation use it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from copilot_ray.registry import get_algorithm
from copilot_ray.settings import effective

# (a spec is a copilot_ray.sweep_spec.models.SweepSpec; not imported: models imports this module)
SweepSpec = Any

MIN_EVALUATIONS = 3
THROUGHPUT_FILE = Path(__file__).resolve().parents[1] / "measured_throughput.json"


@dataclass(frozen=True)
class TrialEstimate:
    label: str  # the configuration (grid point or a corner of the sampled space)
    max_iteration_env_steps: int
    # The most between two points where the trial can stop at its budget or be evaluated: an iteration,
    # or a repetition for an algorithm that ends iterations there (its max_env_steps_past_budget + 1).
    max_env_steps_between_checks: int
    min_evaluations: int | None  # None: no env-step budget to count against
    why: str  # how min_evaluations follows from the cadence


def _points(spec: SweepSpec) -> list[dict[str, Any]]:
    if spec.searcher.type == "grid":
        return spec.grid_points() or [{}]
    return spec.sampled_points() or [{}]


def _setting(entry, merged: dict[str, Any], key: str) -> Any:
    return merged.get(key, entry.settings[key].default if key in entry.settings else None)


def trial_estimates(spec: SweepSpec) -> list[TrialEstimate]:
    """One estimate per configuration (grid) or per corner of the searched space (optuna); [] for an
    algorithm that takes no env steps (the planner-only baselines)."""
    entry = get_algorithm(spec.algorithm)
    if entry.max_iteration_env_steps is None:
        return []
    out = []
    for point in _points(spec):
        label = ", ".join(f"{k}={v}" for k, v in point.items() if k != "seed") or "every trial"
        out.append(run_estimate(entry, spec.merged(point), label, spec.stop.env_steps, spec.stop.iterations))
    return out


def run_estimate(
    entry, merged: dict[str, Any], label: str, budget: int | None, iterations: int | None
) -> TrialEstimate:
    """One run's estimate (a sweep's configuration, or `train`'s run): `entry` the algorithm (it takes
    env steps), `merged` its setting values, the run's env-step `budget` and `iterations` (None: none)."""
    per_iteration = int(entry.max_iteration_env_steps(merged))
    past = entry.max_env_steps_past_budget
    between = per_iteration if past is None else int(past(merged)) + 1
    cadence = int(_setting(entry, merged, "eval_every_env_steps") or 0)
    interval = int(_setting(entry, merged, "eval_interval") or 0)
    if budget is None:  # stops by iterations only
        evals = None if not interval else iterations // interval
        why = f"{iterations} iterations / eval_interval {interval}"
        if cadence:
            evals, why = None, "by env steps, with no env-step budget to count against"
    elif cadence:
        evals = budget // max(cadence, between)
        unit = "iteration" if past is None else "repetition"
        why = f"{budget:,} env steps / max(eval_every_env_steps {cadence:,}, {unit} {between:,})"
    else:
        done = math.ceil(budget / per_iteration)
        if iterations is not None:
            done = min(done, iterations)
        evals = done // interval if interval else 0
        why = (
            f"at least {done} iteration(s) of at most {per_iteration:,} env steps / eval_interval {interval}"
        )
    return TrialEstimate(label, per_iteration, between, evals, why)


def too_few_evaluations(spec: SweepSpec) -> list[str]:
    """Why the plan's trials could end with fewer than `stop.min_evaluations` evaluations (one line each)."""
    need = spec.stop.min_evaluations
    out = []
    for est in trial_estimates(spec):
        if est.min_evaluations is not None and est.min_evaluations < need:
            if spec.stop.env_steps is None:
                fix = "more iterations or a smaller eval_interval"
            else:
                fix = (
                    f"set eval_every_env_steps (e.g. {max(1, spec.stop.env_steps // 10):,}), a larger budget "
                    "or smaller iterations (task_batch_size, repetitions)"
                )
            out.append(
                f"{est.label}: a trial may end with {est.min_evaluations} evaluation(s) ({est.why}); it needs "
                f">= {need} for a curve and a final figure: {fix}; for a smoke run, lower stop.min_evaluations"
            )
    return out


def budget_overshoot(spec: SweepSpec) -> int | None:
    """How far past `stop.env_steps` a trial may run (env steps): Tune checks the budget when an iteration
    ends, so a trial that crosses it by one step finishes that iteration, or, for an algorithm that stops
    there itself (`max_env_steps_past_budget`), that repetition. None without a budget."""
    estimates = trial_estimates(spec)
    if spec.stop.env_steps is None or not estimates:
        return None
    return max(e.max_env_steps_between_checks for e in estimates) - 1


GPU_RATES = "env_steps_per_s_gpu"


def _measured(gpu: bool = False) -> dict[str, Any] | None:
    """The throughput file's figures (`gpu`: its GPU section, with the file's layout: its own machine,
    source(s) and rates), or None without a readable file."""
    try:
        data = json.loads(THROUGHPUT_FILE.read_text())
    except (OSError, ValueError):
        return None
    return data.get(GPU_RATES, {}) if gpu else data


def _source(data: dict[str, Any], key: str) -> str:
    """Where a figure comes from: one measured apart from the others names its own (`sources[key]`)."""
    source = data.get("sources", {}).get(key, data.get("source", "?"))
    return f"{THROUGHPUT_FILE.name}: {data.get('machine', '?')}; {source}"


def measured_rate(algorithm: str, concurrent: int, gpu: bool = False) -> tuple[float, str] | None:
    """(env steps per second of one trial, where the figure comes from), or None without one. `gpu`:
    the figure of a trial holding a GPU share (the file's GPU section, its own machine and source)."""
    data = _measured(gpu)
    rates = (data or {}).get("env_steps_per_s", {}).get(algorithm)
    slot = "lone" if concurrent <= 1 else "side_by_side"
    if not rates or slot not in rates:
        return None
    return float(rates[slot]), _source(data, f"{algorithm}.{slot}")


WARM_START = "warm_start_s_per_phase"


def measured_warm_start_phase(algorithm: str) -> tuple[float, str] | None:
    """(seconds of one planner warm-start phase, where the figure comes from), or None without one: the
    file's `warm_start_s_per_phase` (measured on one torch thread, as `train` runs it)."""
    data = _measured()
    seconds = (data or {}).get(WARM_START, {}).get(algorithm)
    if seconds is None:
        return None
    return float(seconds), _source(data, f"{algorithm}.{WARM_START}")


def _uses_gpu(spec: SweepSpec) -> bool:
    return float(spec.resources.gpus_per_trial) > 0


def wall_seconds(spec: SweepSpec) -> float | None:
    """The plan's estimated wall seconds, or None without a budget or a measured rate."""
    budget = spec.stop.env_steps
    if budget is None or get_algorithm(spec.algorithm).max_iteration_env_steps is None:
        return None
    concurrent = spec.resources.max_concurrent_trials
    found = measured_rate(spec.algorithm, concurrent, gpu=_uses_gpu(spec))
    if found is None:
        return None
    warm = warm_start_seconds(spec)
    # A stacked trial's seeds take turns at the env steps: its seeds' budgets one after another.
    per_trial = budget * spec.seeds_per_trial / found[0] + (warm[0] if warm else 0.0)
    return math.ceil(len(spec.trial_plan()) / concurrent) * per_trial


WARM_START_SETTING = "planner_warm_start"


def warm_start_seconds(spec: SweepSpec) -> tuple[float, float] | None:
    """(wall seconds of a trial's planner warm start, its phases), the mean over the plan's
    configurations, a stacked trial's seeds' warm starts one after another: (0, 0) for an algorithm or
    plan without one, None where one is planned but no seconds per phase are measured."""
    entry = get_algorithm(spec.algorithm)
    if WARM_START_SETTING not in entry.settings:
        return 0.0, 0.0
    points = _points(spec)
    phases = [
        int(effective(entry.settings, spec.merged(p), entry.presets)[WARM_START_SETTING] or 0) for p in points
    ]
    mean = sum(phases) / len(phases)
    if not mean:
        return 0.0, 0.0
    phase = measured_warm_start_phase(spec.algorithm)
    if phase is None:
        return None
    return mean * phase[0] * spec.seeds_per_trial, mean


def _warm_start_text(spec: SweepSpec) -> tuple[str, str]:
    """How the warm start enters a trial's estimate and where its figure comes from ("" without one)."""
    warm = warm_start_seconds(spec)
    if warm is None:
        return "", "; the planner's warm start not counted (no measured seconds per phase)"
    seconds, phases = warm
    if not seconds:
        return "", ""
    per_phase = seconds / phases / spec.seeds_per_trial
    seeds = f" x {spec.seeds_per_trial} seeds" if spec.seeds_per_trial > 1 else ""
    gpu = " (its CPU figure)" if _uses_gpu(spec) else ""
    return (
        f" + the warm start's {phases:,.0f} phases x {per_phase:.2f} s{seeds} = {duration_text(seconds)}",
        f"; the warm start: {THROUGHPUT_FILE.name}'s {spec.algorithm}.{WARM_START}{gpu}",
    )


def total_wall_time_line(specs: list[SweepSpec]) -> str:
    """The parts of a file run one after another: the sum of their estimates."""
    known = [w for w in (wall_seconds(s) for s in specs) if w is not None]
    missing = len(specs) - len(known)
    tail = f" ({missing} part(s) without an estimate not counted)" if missing else ""
    return f"all {len(specs)} parts, one after another: about {duration_text(sum(known))} in all{tail}"


def wall_time_line(spec: SweepSpec) -> str:
    """The plan's estimated wall time, and where the env-steps-per-second figure comes from."""
    budget = spec.stop.env_steps
    if budget is None or get_algorithm(spec.algorithm).max_iteration_env_steps is None:
        return "  wall time: not estimated (no env-step budget to scale a measured rate by)"
    concurrent = spec.resources.max_concurrent_trials
    gpu = _uses_gpu(spec)
    found = measured_rate(spec.algorithm, concurrent, gpu=gpu)
    if found is None:
        if gpu:
            return (
                f"  wall time: not estimated (no env-steps/s measured for {spec.algorithm} on a GPU: "
                f"{THROUGHPUT_FILE.name} has no {GPU_RATES} figure for it yet; scripts/device_check.sh "
                "measures one)"
            )
        return f"  wall time: not estimated (no measured env-steps/s for {spec.algorithm} in {THROUGHPUT_FILE.name})"
    rate, source = found
    waves = math.ceil(len(spec.trial_plan()) / concurrent)
    stacked = spec.seeds_per_trial
    seconds = wall_seconds(spec)
    per_trial = f"{budget:,} env steps" if stacked == 1 else f"{stacked} seeds x {budget:,} env steps"
    warm, warm_source = _warm_start_text(spec)
    return (
        f"  wall time: about {duration_text(seconds)} ({waves} wave(s) x {per_trial} at ~{rate:.0f} env "
        f"steps/s per trial{' side by side' if concurrent > 1 else ''}{warm}; measured on maze-point, other "
        f"envs differ; {source}{warm_source}"
        + (
            "; a stack's speed-up is not counted: 1.07-1.23x on two CPU cores (benchmarks/stacked_trial.py, "
            "u-maze), not measured on a GPU"
            if stacked > 1
            else ""
        )
        + ")"
    )


def duration_text(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def cpu_warning(spec: SweepSpec, available: int | None, where: str) -> str | None:
    """A warning when the plan asks for more CPUs at once than `available` (the machine or cluster)."""
    asked = spec.resources.max_concurrent_trials * (spec.resources.cpus_per_trial or 1)
    if available is None or asked <= available:
        return None
    return (
        f"  warning: {spec.resources.max_concurrent_trials} trial(s) at a time x "
        f"{spec.resources.cpus_per_trial} CPU(s) = {asked} CPUs, but {where} has {available}: trials will "
        "wait for CPUs (lower resources.max_concurrent_trials or num_env_runners, or run on a cluster)"
    )


def local_gpus() -> int:
    """GPUs torch sees on this machine (torch is imported only when a spec asks for GPUs)."""
    import torch

    return int(torch.cuda.device_count())


def gpu_problem(spec: SweepSpec, available: int) -> str | None:
    """Why the plan cannot run on a machine with `available` GPUs (None: it can, or it asks for none)."""
    asked = spec.resources.gpus_per_trial
    if asked <= 0 or asked <= available:
        return None
    return (
        f"resources.gpus_per_trial={asked:g} is invalid: this machine has {available} GPU(s) "
        "(torch.cuda.device_count()); use 0 here, or run on a cluster with GPUs (--address)"
    )
