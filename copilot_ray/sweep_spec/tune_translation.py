"""A validated spec in Ray Tune's and Optuna's terms: stop criteria, search space, scheduler.

Imports ray.tune only inside the functions that return Tune objects: `--check` never imports Ray.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from copilot_ray import keys
from copilot_ray.sweep_spec.models import SweepSpec
from copilot_ray.sweep_spec.sections import ParamSearch


def tune_stop(spec: SweepSpec) -> dict[str, int]:
    """Tune's ``stop`` criteria (either one ends a trial)."""
    stop = {}
    if spec.stop.env_steps is not None:
        stop[keys.ENV_STEPS] = spec.stop.env_steps
    if spec.stop.iterations is not None:
        stop[keys.TRAINING_ITERATION] = spec.stop.iterations
    return stop


def to_tune_search_space(spec: SweepSpec) -> dict[str, Any]:
    """The flat Tune ``param_space`` of the searched keys (dotted names; imports ray.tune).

    grid -> ``tune.grid_search`` (plus ``seed: tune.grid_search(seeds)``, or ``_seeds`` over the seed
    groups with ``seeds_per_trial`` > 1); int -> ``randint`` /
    ``lograndint`` / ``qrandint`` (``high`` inclusive, as in the spec); float -> ``uniform`` /
    ``loguniform`` / ``quniform``; categorical -> ``choice``. Under an optuna searcher the seed is not
    searched (one study per seed: add ``"seed": seed`` per Tuner). Conditional spaces (``when``) cannot be
    written as Tune domains: use ``optuna_define_by_run(spec)`` with ``OptunaSearch(space=...)``.
    """
    if spec.has_conditional_params:
        raise ValueError(
            f"{spec.source}: search has conditional parameters (when); Tune domains cannot express them: "
            "use OptunaSearch(space=optuna_define_by_run(spec))"
        )
    from ray import tune

    space: dict[str, Any] = {}
    for key, ps in spec.search.items():
        d, v = ps.domain, ps.values
        if d == "grid":
            space[key] = tune.grid_search(v)
        elif d == "categorical":
            space[key] = tune.choice(v)
        elif d == "int":
            step = ps.step or 1
            if step == 1:
                space[key] = tune.lograndint(v[0], v[1] + 1) if ps.log else tune.randint(v[0], v[1] + 1)
            else:
                space[key] = tune.qrandint(v[0], v[1], step)
        elif ps.log:
            space[key] = tune.loguniform(v[0], v[1])
        elif ps.step is not None:
            space[key] = tune.quniform(v[0], v[1], ps.step)
        else:
            space[key] = tune.uniform(v[0], v[1])
    if spec.variants:
        space[keys.VARIANT_PARAM] = tune.grid_search(list(spec.variants))
    if len(spec.env.ids) > 1:
        space[keys.ENV_PARAM] = tune.grid_search(spec.env.ids)
    if spec.searcher.type == "grid" and spec.seeds_per_trial > 1:
        space[keys.SEEDS_KEY] = tune.grid_search(spec.seed_groups())  # a stacked trial's seeds
    elif spec.searcher.type == "grid":
        space[keys.SEED_PARAM] = tune.grid_search(list(spec.seeds))
    return space


_OPTUNA_SCALARS = (str, int, float, bool, type(None))


def optuna_define_by_run(spec: SweepSpec) -> Callable[[Any], dict[str, Any]]:
    """``fn(trial) -> dict``: suggests every searched parameter, conditional ones only in their branch.

    Works with a plain ``optuna.Trial`` (``study.ask()``) and with Ray's ``OptunaSearch(space=fn)``. The
    returned dict holds all drawn values (flat, dotted keys); categorical values Optuna cannot store
    (mappings, lists) are suggested by their label ``"0", "1", ...`` and returned decoded, which also
    overrides the label in Ray's merged config. No ray import.
    """
    params = dict(spec.search)

    def suggest(trial: Any, params: Mapping[str, ParamSearch], out: dict[str, Any]) -> None:
        for key, ps in params.items():
            d, v = ps.domain, ps.values
            if d == "int":
                out[key] = trial.suggest_int(key, v[0], v[1], step=ps.step or 1, log=ps.log)
            elif d == "float":
                out[key] = trial.suggest_float(key, float(v[0]), float(v[1]), log=ps.log, step=ps.step)
            else:  # categorical (grid is rejected under optuna; accepted here as a categorical)
                if all(isinstance(x, _OPTUNA_SCALARS) for x in v):
                    out[key] = trial.suggest_categorical(key, v)
                else:
                    label = trial.suggest_categorical(key, [str(i) for i in range(len(v))])
                    out[key] = v[int(label)]
                branch = (ps.when or {}).get(str(out[key]))
                if branch:
                    suggest(trial, branch, out)

    def define_by_run(trial: Any) -> dict[str, Any]:
        out: dict[str, Any] = {}
        suggest(trial, params, out)
        return out

    return define_by_run


def to_tune_scheduler(spec: SweepSpec) -> Any:
    """Tune's scheduler for ``spec.scheduler`` (None if none), timed in env steps. Imports ray.tune."""
    sch = spec.scheduler
    if sch is None:
        return None
    from ray.tune.schedulers import ASHAScheduler, MedianStoppingRule

    common = {"time_attr": keys.ENV_STEPS, "metric": spec.searcher.metric, "mode": spec.searcher.mode}
    if sch.type == "asha":
        return ASHAScheduler(
            max_t=sch.max_t, grace_period=sch.grace_period, reduction_factor=sch.reduction_factor, **common
        )
    return MedianStoppingRule(
        grace_period=sch.grace_period, min_samples_required=sch.min_samples_required, **common
    )
