"""The trial plan in words, for ``--check``: what runs, how many trials, the budget."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from copilot_ray import keys
from copilot_ray.registry import get_algorithm
from copilot_ray.sweep_spec.estimate import budget_overshoot, cpu_warning, trial_estimates, wall_time_line

if TYPE_CHECKING:  # annotations only: models imports this module
    from copilot_ray.sweep_spec.models import SweepSpec
    from copilot_ray.sweep_spec.sections import ParamSearch


def format_plan(
    spec: SweepSpec,
    tracking_uri: str | None = None,
    cpus_available: int | None = None,
    where: str = "this machine",
) -> str:
    """What runs (a table of grid points, or the sampled space), how many trials, the budget, the
    evaluations a trial gets and the wall time to expect; `tracking_uri`: the store the run will use
    (a --tracking-uri override), `cpus_available`: the machine's or cluster's CPUs (a warning when the
    plan asks for more)."""
    lines = [
        f"sweep {spec.name!r} ({spec.source}): {spec.algorithm} on {', '.join(spec.env.ids)} "
        f"{spec.env.config or ''}"
    ]
    if spec.description:
        lines.append(f"  {spec.description.strip()}")
    uri = tracking_uri or spec.tracking.uri
    given = " (--tracking-uri)" if tracking_uri else ""
    lines.append(f"  MLflow experiment {spec.experiment!r} at {uri}{given}")
    if spec.config:
        lines.append("  fixed: " + ", ".join(f"{k}={v!r}" for k, v in spec.config.items()))
    for name, overrides in spec.variants.items():
        text = ", ".join(f"{k}={v!r}" for k, v in overrides.items()) or "(config as it is)"
        lines.append(f"  variant {name}: {text}")
    if spec.best_of is not None:
        b = spec.best_of
        if b.chosen is None:
            lines.append(
                f"  best_of: the searched values of sweep {b.sweep!r}'s best configuration by {b.mode} "
                f"{b.metric} (read from its MLflow store when this part starts)"
            )
        else:
            lines.append(f"  best_of {b.sweep!r}: " + ", ".join(f"{k}={v!r}" for k, v in b.chosen.items()))
    lines.extend(_what_runs(spec))
    if spec.scheduler is not None:
        sch = spec.scheduler
        args = {k: v for k, v in sch.model_dump().items() if k != "type" and v is not None}
        lines.append(f"  scheduler: {sch.type} on {keys.ENV_STEPS} {args}")
    lines.extend(_budget_lines(spec))
    lines.append(wall_time_line(spec))
    if warning := cpu_warning(spec, cpus_available, where):
        lines.append(warning)
    return "\n".join(lines)


def _what_runs(spec: SweepSpec) -> list[str]:
    """The grid's configurations as a table, or the searched space and the first trial of each study."""
    lines = []
    seeds = ", ".join(str(s) for s in spec.seeds)
    if spec.searcher.type == "grid":
        points = spec.grid_points()
        columns = (
            (["variant"] if spec.variants else [])
            + ([keys.ENV_PARAM] if len(spec.env.ids) > 1 else [])
            + list(spec.search)
        )
        if spec.seeds_per_trial > 1:  # a trial per group: "0, 1, 2 | 3, 4, 5"
            seeds = " | ".join(", ".join(str(s) for s in group) for group in spec.seed_groups())
        header = ["#", *columns, "seeds"]
        rows = [[str(i + 1), *(_cell(p[k]) for k in columns), seeds] for i, p in enumerate(points)]
        widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]
        lines.append(f"  grid: {len(points)} configuration(s) x {len(spec.seeds)} seed(s)")
        if spec.seeds_per_trial > 1:
            lines.append(
                f"  {spec.seeds_per_trial} seeds per trial: each trial steps its seeds together in one "
                "process, one batched act per env step and one stacked SAC update per round on every "
                "device (each seed still its own MLflow run)"
            )
        for row in [header, *rows]:
            lines.append(
                "    " + "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
            )
    else:
        s = spec.searcher
        lines.append(
            f"  optuna {s.sampler}: {s.mode} {s.metric}, {s.num_samples} sample(s) per seed, "
            f"seeds [{seeds}] (one study per seed, sampler seed {s.seed} + index)"
        )
        lines.extend(_describe_space(spec.search, "    "))
        first = default_point(spec)
        if first:
            lines.append(
                "    first trial of each study: the defaults "
                + ", ".join(f"{k}={v!r}" for k, v in first.items())
            )
    return lines


def _budget_lines(spec: SweepSpec) -> list[str]:
    """Trials, env steps, concurrency and CPUs; checkpoints and retries; each trial's iteration size,
    evaluations and how far past the budget it may run."""
    lines = []
    b = spec.budget()
    stop = " and ".join(
        t
        for t in (
            f"{spec.stop.env_steps} env steps" if spec.stop.env_steps else "",
            f"{spec.stop.iterations} iterations" if spec.stop.iterations else "",
        )
        if t
    )
    lines.append(
        f"  {b['trials']} trial(s), each stops at {stop}; "
        + (f"at most {b['env_steps']:,} env steps in all; " if b["env_steps"] else "")
        + f"{spec.resources.max_concurrent_trials} at a time ({b['waves']} wave(s)), "
        f"{spec.resources.cpus_per_trial} CPU(s) per trial, {b['cpus']} CPU(s) in use"
        + (
            f", {spec.resources.gpus_per_trial:g} GPU(s) per trial (the learner)"
            if spec.resources.gpus_per_trial
            else ""
        )
    )
    ft = spec.fault_tolerance
    retries = "without limit" if ft.max_failures == -1 else f"up to {ft.max_failures} time(s)"
    lines.append(
        f"  a checkpoint every {ft.checkpoint_every} iteration(s); a failed trial is retried from it {retries}"
    )
    for est in trial_estimates(spec):
        evals = "" if est.min_evaluations is None else f"; evaluations per trial >= {est.min_evaluations}"
        lines.append(f"  {est.label}: env steps per iteration <= {est.max_iteration_env_steps:,}{evals}")
    if (over := budget_overshoot(spec)) is not None:
        lines.append(
            f"  a trial may run up to {over:,} env steps ({100 * over / spec.stop.env_steps:.0f} %) past "
            + (
                "stop.env_steps (its last iteration ends at the first repetition past it)"
                if get_algorithm(spec.algorithm).max_env_steps_past_budget is not None
                else "stop.env_steps (the budget is checked when an iteration ends)"
            )
        )
    return lines


def default_point(spec: SweepSpec) -> dict[str, Any]:
    """Every searched setting at its default, when each default lies in its domain and no parameter is
    conditional: an Optuna study tries this point first (so the defaults always compete). {} otherwise."""
    from copilot_ray.registry import get_algorithm

    if spec.searcher.type != "optuna" or spec.has_conditional_params:
        return {}
    settings = get_algorithm(spec.algorithm).settings
    point = {}
    for key, ps in spec.search.items():
        value = settings[key].default
        inside = (
            value in ps.values
            if ps.domain in ("grid", "categorical")
            else (value is not None and ps.values[0] <= value <= ps.values[1])
        )
        if not inside:
            return {}
        point[key] = value
    return point


def _cell(value: Any) -> str:
    return value if isinstance(value, str) else repr(value)


def _describe_space(params: Mapping[str, ParamSearch], indent: str) -> list[str]:
    out = []
    for key, ps in params.items():
        out.append(f"{indent}{key}: {ps.describe()}")
        for choice, branch in (ps.when or {}).items():
            out.append(f"{indent}  when {key} = {choice}:")
            out.extend(_describe_space(branch, indent + "    "))
    return out
