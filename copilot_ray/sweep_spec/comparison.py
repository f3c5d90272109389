"""The parts of one spec file that share an MLflow experiment are a comparison, and a comparison is fair
by construction: checked here before anything runs.

Among the parts whose algorithm learns from env steps (it has the ``eval_every_env_steps`` setting;
the planner-only baselines count collision checks instead), every part of one experiment must have

* the same env (ids and config), the same env-step budget (``stop.env_steps``),
* the same evaluation: ``eval_every_env_steps`` set (> 0) and equal, so every method is evaluated on
  one env-step cadence whatever its iteration size, and the same ``eval_num_tasks``,
* the same tuning budget: parts that search get the same searcher type, number of trials per seed and
  seeds (and so, with the budget above, the same env steps of tuning).

A part with ``best_of`` (stage 2) must name a sweep; when that sweep is a part of the same file, it must
run the same algorithm and log the metric, and its store and experiment are where stage 2 looks.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from typing import Any

from copilot_ray.registry import get_algorithm, metric_known
from copilot_ray.sweep_spec.errors import did_you_mean

# (a spec is a copilot_ray.sweep_spec.models.SweepSpec; not imported: models imports this module)
SweepSpec = Any

CADENCE = "eval_every_env_steps"


def _effective(spec: SweepSpec, key: str) -> Any:
    """A setting's value in every trial of the part (config, else its default); variants may differ."""
    settings = get_algorithm(spec.algorithm).settings
    return spec.config.get(key, settings[key].default if key in settings else None)


def _learns_from_env_steps(spec: SweepSpec) -> bool:
    return CADENCE in get_algorithm(spec.algorithm).settings


def link_stages(specs: Sequence[SweepSpec]) -> list[str]:
    """Points every best_of at its sweep's store when that sweep is a part of the file; problems."""
    by_name = {s.name: s for s in specs}
    problems = []
    for spec in specs:
        b = spec.best_of
        if b is None or b.sweep not in by_name:
            if b is not None and b.uri is None and len(specs) > 1:
                problems.append(
                    f"{spec.source}: {spec.name}: best_of.sweep: {b.sweep!r} is invalid: not a part of this "
                    f"file (name one, or give best_of.uri for a sweep run elsewhere)"
                    f"{did_you_mean(b.sweep, list(by_name))}"
                )
            continue
        tuned = by_name[b.sweep]
        spec._best_of_store = (tuned.tracking.uri, tuned.experiment)
        where = f"{spec.source}: {spec.name}: best_of"
        if tuned.algorithm != spec.algorithm:
            problems.append(
                f"{where}.sweep: {b.sweep!r} is invalid: it runs {tuned.algorithm}, this part {spec.algorithm}"
            )
        if not tuned.search:
            problems.append(f"{where}.sweep: {b.sweep!r} is invalid: it searches nothing to choose from")
        if not metric_known(b.metric, get_algorithm(tuned.algorithm).metrics):
            problems.append(f"{where}.metric: {b.metric!r} is invalid: {tuned.algorithm} does not log it")
    return problems


def comparison_problems(specs: Sequence[SweepSpec]) -> list[str]:
    """What makes a comparison (parts sharing an experiment) unfair, one line each."""
    groups: dict[str, list[SweepSpec]] = defaultdict(list)
    for spec in specs:
        if _learns_from_env_steps(spec):
            groups[spec.experiment].append(spec)
    problems = []
    for experiment, parts in groups.items():
        if len(parts) < 2:
            continue
        problems += _differences(experiment, parts)
    return problems


OVERSHOOT_GAP = 0.05  # of the budget: a larger difference in how far parts may run past it is said


def overshoot_warnings(specs: Sequence[SweepSpec]) -> list[str]:
    """Warnings (not refusals: it is the iterations' size, a method's own) where the parts of a comparison
    may run unequally far past their common env-step budget, or be evaluated unequally often: an
    algorithm evaluates when an iteration (or, for one that ends iterations early there, a repetition)
    ends, so iterations longer than ``eval_every_env_steps`` space its evaluations further apart."""
    from copilot_ray.sweep_spec.estimate import budget_overshoot, trial_estimates

    groups: dict[str, list[SweepSpec]] = defaultdict(list)
    for spec in specs:
        if _learns_from_env_steps(spec) and spec.stop.env_steps:
            groups[spec.experiment].append(spec)
    out = []
    for experiment, parts in groups.items():
        if len(parts) < 2:
            continue
        budget = parts[0].stop.env_steps
        shares = {p.name: (budget_overshoot(p) or 0) / p.stop.env_steps for p in parts}
        if max(shares.values()) - min(shares.values()) > OVERSHOOT_GAP:
            shown = ", ".join(f"{name} {100 * share:.0f} %" for name, share in shares.items())
            out.append(
                f"warning: experiment {experiment!r}: its parts may run past the {budget:,} env-step budget "
                f"by up to: {shown} (the budget is checked when an iteration ends, or a repetition where "
                "an algorithm stops there), so their env steps may differ by that much; the report reads "
                "final success and the AUC at the budget, so the extra env steps do not reach them: raise "
                "the budget or shrink the large iterations (task_batch_size, repetitions) to narrow it"
            )
        spacing = {
            p.name: max(
                [int(_effective(p, CADENCE) or 0)]
                + [e.max_env_steps_between_checks for e in trial_estimates(p)]
            )
            for p in parts
        }
        if max(spacing.values()) > min(spacing.values()) * (1 + OVERSHOOT_GAP):
            shown = ", ".join(f"{name} {steps:,}" for name, steps in spacing.items())
            out.append(
                f"warning: experiment {experiment!r}: its parts' evaluations may be up to this many env "
                f"steps apart: {shown} (one at the end of the first iteration past each multiple of "
                f"{CADENCE}, and some iterations or repetitions are longer than that), so some curves have "
                "fewer points; "
                "shrink the large iterations (task_batch_size, repetitions) to even them out"
            )
    return out


def _differences(experiment: str, parts: list[SweepSpec]) -> list[str]:
    out = []
    first = parts[0]

    def differ(what: str, value_of, why: str) -> None:
        values = {p.name: value_of(p) for p in parts}
        if len({repr(v) for v in values.values()}) > 1:
            shown = ", ".join(f"{name}: {v!r}" for name, v in values.items())
            out.append(
                f"{first.source}: experiment {experiment!r}: {what} differs between its parts ({shown}): {why}"
            )

    differ("env", lambda p: (p.env.ids, p.env.config), "a comparison runs every method on the same env")
    differ("stop.env_steps", lambda p: p.stop.env_steps, "every method gets the same env-step budget")
    differ(
        "eval_num_tasks",
        lambda p: _effective(p, "eval_num_tasks"),
        "every method is evaluated on the same tasks",
    )
    for p in parts:
        cadence = _effective(p, CADENCE)
        if not cadence or any(CADENCE in v for v in p.variants.values()):
            out.append(
                f"{p.source}: {p.name}: config.{CADENCE}: {cadence!r} is invalid: the parts of experiment "
                f"{experiment!r} are a comparison; give every part the same {CADENCE} > 0 in config, so that "
                "methods whose iterations differ in size are evaluated on one env-step cadence"
            )
    differ(CADENCE, lambda p: _effective(p, CADENCE), "every method is evaluated on one env-step cadence")
    searching = [p for p in parts if p.search]
    if searching and len(searching) < len(parts):
        names = ", ".join(p.name for p in parts if not p.search)
        out.append(
            f"{first.source}: experiment {experiment!r}: {names} search nothing while other parts tune: "
            "every method gets the same tuning budget (put tuning in an experiment of its own)"
        )
    if len(searching) > 1:
        parts = searching
        differ("searcher.type", lambda p: p.searcher.type, "every method gets the same tuning budget")
        differ(
            "trials per seed",
            lambda p: len(p.trial_plan()) * p.seeds_per_trial // len(p.seeds),
            "the same tuning budget",
        )
        differ("seeds", lambda p: list(p.seeds), "every method is tuned on the same seeds")
    return out
