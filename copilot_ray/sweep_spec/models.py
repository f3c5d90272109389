"""The sweep spec's schema (pydantic models) and its validation, section by section and across sections."""

from __future__ import annotations

import copy
import itertools
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, PrivateAttr, model_validator

from copilot_ray import keys
from copilot_ray.envs import env_ids, make
from copilot_ray.envs.maze.layouts import LayoutError
from copilot_ray.registry import (
    ALGORITHMS,
    AlgorithmEntry,
    RunContext,
    UnknownAlgorithmError,
    algorithm_names,
    get_algorithm,
    metric_known,
    stackable_algorithms,
)
from copilot_ray.settings import Setting
from copilot_ray.settings import problems as setting_problems
from copilot_ray.sweep_spec.errors import Issue, Issues, SpecError, did_you_mean
from copilot_ray.sweep_spec.estimate import too_few_evaluations
from copilot_ray.sweep_spec.sections import (
    EnvSpec,
    FaultToleranceSpec,
    ParamSearch,
    ResourcesSpec,
    SchedulerSpec,
    SearcherSpec,
    StopSpec,
    TrackingSpec,
    _Model,
    _number,
)

# `search: declared`: the algorithm's own search space (its settings module's SEARCH_SPACE).
DECLARED = "declared"


class BestOfSpec(_Model):
    """Stage 2 of a comparison: this part's configuration is the best trial of another sweep (stage 1),
    read from the MLflow store when the part starts, never from a hand edit. ``metric`` (a validation
    metric) ranks that sweep's finished trials, averaged over their seeds; the winner's searched values
    become this part's fixed config. The resolved spec the part runs with records them in ``chosen``
    (and the runs they came from in ``chosen_from``), so a resumed part keeps them."""

    sweep: str
    metric: str
    mode: Literal["max", "min"] = "max"
    uri: str | None = None  # the store of that sweep (default: its part in this file, else this part's)
    experiment: str | None = None  # its MLflow experiment (default: as for uri)
    chosen: dict[str, Any] | None = None
    chosen_from: str | None = None


# The agent settings a seed stack needs at their defaults (algorithms/sac/settings.py; seed_stack.py)
STACK_NEEDS = ("fast_learner", "fused_update", "lean_traversal")


class SweepSpec(_Model):
    name: str
    experiment: str | None = None
    description: str | None = None
    env: EnvSpec
    algorithm: str = "copilot"
    config: dict[str, Any] = Field(default_factory=dict)
    variants: dict[str, dict[str, Any]] = Field(default_factory=dict)
    search: dict[str, ParamSearch] = Field(default_factory=dict)
    best_of: BestOfSpec | None = None
    seeds: list[int] = Field(default_factory=lambda: [0])
    # Seeds trained together in one trial, on a GPU their SAC updates stacked (consecutive groups of `seeds`);
    # 1: a trial per seed (copilot_ray.algorithms.sac.trial).
    seeds_per_trial: int = 1
    searcher: SearcherSpec = Field(default_factory=SearcherSpec)
    scheduler: SchedulerSpec | None = None
    stop: StopSpec
    resources: ResourcesSpec = Field(default_factory=ResourcesSpec)
    fault_tolerance: FaultToleranceSpec = Field(default_factory=FaultToleranceSpec)
    tracking: TrackingSpec = Field(default_factory=TrackingSpec)

    _source: str = PrivateAttr(default="<spec>")
    _document: Any = PrivateAttr(default=None)  # the mapping it was parsed from, as written
    # best_of's sweep when it is a part of the same file: its store and experiment (load_specs sets them)
    _best_of_store: tuple[str, str] | None = PrivateAttr(default=None)

    @model_validator(mode="before")
    @classmethod
    def _declared_search(cls, data: Any) -> Any:
        """`search: declared` -> the algorithm's own search space (SEARCH_SPACE of its settings)."""
        if not (isinstance(data, dict) and data.get("search") == DECLARED):
            return data
        try:
            entry = get_algorithm(data.get("algorithm", "copilot"))
        except (UnknownAlgorithmError, TypeError):
            return {**data, "search": {}}  # the algorithm's own error says what is wrong
        if not entry.search_space:
            raise Issue(
                "search",
                DECLARED,
                f"{entry.name} declares no search space (SEARCH_SPACE in {ALGORITHMS[entry.name][0]}); "
                "give the domains here",
            )
        return {**data, "search": copy.deepcopy(dict(entry.search_space))}

    # ------------------------------------------------------------------ validation across sections
    @model_validator(mode="after")
    def _check(self) -> SweepSpec:
        issues: list[Issue] = []
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", self.name):
            issues.append(Issue("name", self.name, "use letters, digits, '_', '-', '.' (it names a folder)"))
        self.experiment = self.experiment or self.name
        try:
            entry = get_algorithm(self.algorithm)
        except UnknownAlgorithmError:
            names = algorithm_names()
            issues.append(
                Issue(
                    "algorithm",
                    self.algorithm,
                    f"unknown algorithm{did_you_mean(self.algorithm, names)}; known: {names}",
                )
            )
            raise Issues(issues) from None
        issues += self._check_env()
        issues += self._check_config(entry.settings)
        issues += self._check_variants(entry.settings)
        issues += self._check_search(entry.settings)
        issues += self._check_seeds()
        issues += self._check_seed_stacking(entry)
        issues += self._check_searcher(entry)
        issues += self._check_best_of(entry.settings)
        if self.resources.gpus_per_trial > 0 and not entry.gpu_learner:
            issues.append(
                Issue(
                    "resources.gpus_per_trial",
                    _number(self.resources.gpus_per_trial),
                    f"{self.algorithm!r} has no learner that runs on a GPU (a planner-only baseline): use 0",
                )
            )
        if not issues:
            issues += self._check_combinations(entry)
        if not issues:
            where = "stop.env_steps" if self.stop.env_steps is not None else "stop.iterations"
            budget = self.stop.env_steps if self.stop.env_steps is not None else self.stop.iterations
            issues += [Issue(where, budget, why) for why in too_few_evaluations(self)]
        storage = Path(self.tracking.storage).expanduser().resolve()
        self.tracking.storage = str(storage)
        if self.tracking.uri is None:
            self.tracking.uri = f"sqlite:///{storage / self.name / 'mlflow.db'}"
        elif self.tracking.uri.startswith("sqlite:///") and not self.tracking.uri.startswith("sqlite:////"):
            # A relative SQLite file, like a relative storage, is where the sweep was started.
            db = Path(self.tracking.uri[len("sqlite:///") :]).expanduser().resolve()
            self.tracking.uri = f"sqlite:///{db}"
        if issues:
            raise Issues(issues)
        return self

    def _check_env(self) -> list[Issue]:
        if not self.env.ids or len(set(self.env.ids)) != len(self.env.ids):
            return [Issue("env.id", self.env.id, "give one env id, or a list of distinct ones")]
        if len(self.env.ids) > 1 and self.searcher.type != "grid":
            return [Issue("env.id", self.env.id, "several envs need searcher type: grid")]
        issues = []
        for i, env_id in enumerate(self.env.ids):
            path = "env.id" if isinstance(self.env.id, str) else f"env.id[{i}]"
            issues += self._check_one_env(env_id, path)
        return issues

    def _check_one_env(self, env_id: str, id_path: str) -> list[Issue]:
        ids = env_ids()
        if env_id not in ids:
            return [Issue(id_path, env_id, f"unknown env id{did_you_mean(env_id, ids)}; known: {ids}")]
        try:
            make(env_id, **self.env.config).close()
        except Exception as err:  # noqa: BLE001 - any failure to build is a spec error, named below
            path = "env.config"
            text = str(err)
            named = [
                k
                for k, v in self.env.config.items()
                if f"'{k}'" in text or f"{k}=" in text or f"{k} {v!r}" in text
            ]
            if named:
                path = f"env.config.{named[0]}"
            elif isinstance(err, LayoutError) and "layout" in self.env.config:
                path = "env.config.layout"
            value = self.env.config.get(path[len("env.config.") :], self.env.config)
            return [Issue(path, value, f"building env {env_id!r} failed: {type(err).__name__}: {text}")]
        return []

    def _check_config(self, settings: Mapping[str, Setting]) -> list[Issue]:
        issues = []
        for key, value in self.config.items():
            if key not in settings:
                issues.append(
                    Issue(
                        f"config.{key}",
                        value,
                        f"unknown key{did_you_mean(key, settings)} (known keys: the SETTINGS of {ALGORITHMS[self.algorithm][0]})",
                        show_value=False,
                    )
                )
            elif msg := rule_problem(key, settings[key], value):
                issues.append(Issue(f"config.{key}", value, msg))
        if "seed" in self.config:
            issues.append(
                Issue("config.seed", self.config["seed"], "seeds are set by the top-level `seeds` list")
            )
        if "alpha_schedule" in self.config and "alpha_schedule.kind" in self.config:
            issues.append(
                Issue(
                    "config.alpha_schedule.kind",
                    self.config["alpha_schedule.kind"],
                    "give either alpha_schedule (preset or mapping) or alpha_schedule.kind with its fields, not both",
                )
            )
        return issues

    def _check_variants(self, settings: Mapping[str, Setting]) -> list[Issue]:
        issues = []
        if self.variants and self.searcher.type != "grid":
            issues.append(Issue("variants", list(self.variants), "variants need searcher type: grid"))
        for name, overrides in self.variants.items():
            if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
                issues.append(Issue(f"variants.{name}", name, "use letters, digits, '_', '-', '.'"))
            if not isinstance(overrides, dict):
                issues.append(Issue(f"variants.{name}", overrides, "must be a mapping of config keys"))
                continue
            for key, value in overrides.items():
                path = f"variants.{name}.{key}"
                if key not in settings:
                    issues.append(
                        Issue(path, value, f"unknown key{did_you_mean(key, settings)}", show_value=False)
                    )
                elif msg := rule_problem(key, settings[key], value):
                    issues.append(Issue(path, value, msg))
                elif key in self.search:
                    issues.append(Issue(path, value, f"{key} is also searched; keep one"))
        return issues

    def _check_search(self, settings: Mapping[str, Setting]) -> list[Issue]:
        issues: list[Issue] = []
        seen: dict[str, str] = {}

        def walk(params: Mapping[str, ParamSearch], prefix: str, fixed_here: set[str]) -> None:
            for key, ps in params.items():
                path = f"{prefix}.{key}"
                if key not in settings:
                    issues.append(
                        Issue(path, key, f"unknown key{did_you_mean(key, settings)}", show_value=False)
                    )
                    continue
                if key in self.config:
                    issues.append(
                        Issue(path, key, f"{key} is also fixed in config; keep one", show_value=False)
                    )
                if key in fixed_here:
                    issues.append(
                        Issue(path, key, f"{key} is already searched at {seen[key]}", show_value=False)
                    )
                seen.setdefault(key, path)
                issues.extend(_check_domain(key, ps, settings[key], path))
                if ps.when:
                    for choice, branch in ps.when.items():
                        walk(branch, f"{path}.when.{choice}", fixed_here | set(params))
                if key == "alpha_schedule.kind" and (
                    "alpha_schedule" in self.config or "alpha_schedule" in self.search
                ):
                    issues.append(
                        Issue(
                            path,
                            key,
                            "searching alpha_schedule.kind excludes alpha_schedule",
                            show_value=False,
                        )
                    )

        walk(self.search, "search", set())
        return issues

    def _check_seeds(self) -> list[Issue]:
        if not self.seeds:
            return [Issue("seeds", self.seeds, "list at least one seed")]
        issues = [Issue(f"seeds[{i}]", s, "seeds must be >= 0") for i, s in enumerate(self.seeds) if s < 0]
        dupes = [s for i, s in enumerate(self.seeds) if s in self.seeds[:i]]
        if dupes:
            issues.append(
                Issue("seeds", self.seeds, f"duplicate seed {dupes[0]} would run the same trial twice")
            )
        return issues

    def _check_seed_stacking(self, entry: AlgorithmEntry) -> list[Issue]:
        """`seeds_per_trial`: groups `seeds` evenly, under a grid, for an agent whose update stacks."""
        n = self.seeds_per_trial
        if n == 1:
            return []
        where = "seeds_per_trial"
        if n < 1:
            return [Issue(where, n, "must be >= 1 (1: a trial per seed)")]
        if len(self.seeds) % n:
            return [
                Issue(where, n, f"must divide the {len(self.seeds)} seeds {self.seeds} into equal groups")
            ]
        if not entry.seed_stack:
            return [
                Issue(
                    where,
                    n,
                    f"{entry.name!r} has no stacked update (SEED_STACK in its settings module); "
                    "stackable: " + ", ".join(stackable_algorithms()),
                )
            ]
        if self.searcher.type != "grid":
            return [
                Issue(
                    where, n, "needs searcher.type grid (a search runs one study per seed, a trial per seed)"
                )
            ]
        if self.resources.num_env_runners != 0:
            return [
                Issue(
                    where,
                    n,
                    f"needs resources.num_env_runners 0, got {self.resources.num_env_runners} (the stacked "
                    "seeds step their envs in the trial's own process)",
                )
            ]
        # A stack's seeds step in one loop with the lean traversal (each drawing its own noise) and
        # update through the fused step (each from its own streams), on any device.
        slow = {
            key: [p for p in self.grid_points() if self.merged(p).get(key) is False] for key in STACK_NEEDS
        }
        for key, points in slow.items():
            if points:
                named = ", ".join(sorted({_point_label(p) for p in points}))
                return [
                    Issue(
                        where,
                        n,
                        f"stacked seeds need {key}: true (they step in one loop with the lean traversal "
                        f"and update through the fused step), and it is false in: {named}",
                    )
                ]
        return []

    def seed_groups(self) -> list[list[int]]:
        """The seeds of each trial: one each, or consecutive groups of `seeds_per_trial`."""
        n = self.seeds_per_trial
        return [list(self.seeds[i : i + n]) for i in range(0, len(self.seeds), n)]

    def _check_searcher(self, entry: AlgorithmEntry) -> list[Issue]:
        issues = []
        s = self.searcher
        for path, metric in (("searcher.metric", s.metric),):
            if metric is not None and keys.is_test_metric(metric):
                issues.append(Issue(path, metric, _test_metric_problem(metric, self.scheduler)))
            elif metric is not None and not metric_known(metric, entry.metrics):
                names = [m.replace("<k>", "0") for m in entry.metrics]
                issues.append(
                    Issue(
                        path,
                        metric,
                        f"{self.algorithm} does not log this metric{did_you_mean(metric, names)}; "
                        f"it logs {list(entry.metrics)}",
                    )
                )
        for key, ps in _all_params(self.search):
            if s.type == "grid" and ps.domain != "grid":
                issues.append(
                    Issue(f"search.{key}", ps.domain, "a grid searcher needs every domain to be grid")
                )
            if s.type == "optuna" and ps.domain == "grid":
                issues.append(
                    Issue(
                        f"search.{key}",
                        "grid",
                        "an optuna searcher samples; use categorical (or searcher type: grid)",
                    )
                )
        if s.type == "optuna" and not self.search:
            issues.append(Issue("search", {}, "an optuna searcher needs at least one searched parameter"))
        if self.scheduler is not None and s.metric is None:
            issues.append(
                Issue("scheduler", self.scheduler.type, "a scheduler needs searcher.metric and searcher.mode")
            )
        return issues

    def _check_best_of(self, settings: Mapping[str, Setting]) -> list[Issue]:
        b = self.best_of
        if b is None:
            return []
        issues = []
        if keys.is_test_metric(b.metric):
            issues.append(Issue("best_of.metric", b.metric, _test_metric_problem(b.metric, None)))
        if self.search:
            issues.append(
                Issue(
                    "best_of",
                    b.sweep,
                    "a part that takes the best configuration of another sweep searches nothing; drop search",
                )
            )
        if b.sweep == self.name:
            issues.append(Issue("best_of.sweep", b.sweep, "names this part itself; name the tuning sweep"))
        for key, value in (b.chosen or {}).items():
            if key not in settings:
                issues.append(
                    Issue(f"best_of.chosen.{key}", value, f"unknown key{did_you_mean(key, settings)}")
                )
            elif msg := rule_problem(key, settings[key], value):
                issues.append(Issue(f"best_of.chosen.{key}", value, msg))
            elif key in self.config:
                issues.append(
                    Issue(f"best_of.chosen.{key}", value, f"{key} is also fixed in config; keep one")
                )
        return issues

    def best_of_store(self, tracking_uri: str | None = None) -> tuple[str, str]:
        """(MLflow URI, experiment) holding `best_of.sweep`'s trials: best_of's own, else that sweep's
        part of this file (under a --tracking-uri override: the override), else this part's."""
        b = self.best_of
        if b is None:
            raise ValueError(f"sweep {self.name!r} has no best_of")
        sibling_uri, sibling_experiment = self._best_of_store or (self.tracking.uri, self.experiment)
        return (b.uri or tracking_uri or sibling_uri, b.experiment or sibling_experiment)

    def _check_combinations(self, entry: AlgorithmEntry) -> list[Issue]:
        """Keys valid one by one can clash together (an alpha schedule missing a field): try them."""
        points = self.grid_points() if self.searcher.type == "grid" else _representative_points(self.search)
        issues: list[Issue] = []
        reported: set[str] = set()
        for point in points:
            for involved, value, why in entry.combination_problems(self.merged(point)):
                if why in reported:  # the same clash at every grid point: say it once
                    continue
                reported.add(why)
                where = "search" if set(involved) & set(point) else "config"
                issues.append(Issue(where, value, why))
        return issues

    # ------------------------------------------------------------------ the plan
    @property
    def source(self) -> str:
        return self._source

    @property
    def document(self) -> dict[str, Any]:
        """A copy of the mapping this spec was parsed from (its own part of a several-spec file)."""
        return copy.deepcopy(self._document) if self._document is not None else self.model_dump()

    @property
    def searched_keys(self) -> list[str]:
        return [k for k, _ in _all_params(self.search)]

    @property
    def has_conditional_params(self) -> bool:
        return any(ps.when for _, ps in _all_params(self.search))

    def sampled_points(self) -> list[dict[str, Any]]:
        """A few flat points of a searched space (every conditional branch, ranges at both ends)."""
        return _representative_points(self.search)

    def grid_points(self) -> list[dict[str, Any]]:
        keys = list(self.search)
        values = [self.search[k].values for k in keys]
        points = [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*values)]
        return self._with_variants(points)

    def _with_variants(self, points: list[dict[str, Any]]) -> list[dict[str, Any]]:
        if len(self.env.ids) > 1:
            points = [{keys.ENV_PARAM: env_id, **p} for env_id in self.env.ids for p in points]
        if not self.variants:
            return points
        return [
            {"variant": name, **p} for name in self.variants for p in points if "variant" not in p
        ] or points

    def merged(self, point: Mapping[str, Any]) -> dict[str, Any]:
        """A trial's effective fixed keys: ``config``, its variant's overrides, then its own values."""
        rest = {k: v for k, v in point.items() if k not in ("variant", "seed", keys.ENV_PARAM)}
        chosen = (self.best_of.chosen or {}) if self.best_of is not None else {}
        return {**self.config, **chosen, **self.variants.get(point.get("variant"), {}), **rest}

    def num_configurations(self) -> int:
        if self.searcher.type == "grid":
            return (
                max(1, len(self.variants))
                * len(self.env.ids)
                * math.prod(len(ps.values) for ps in self.search.values())
            )
        return int(self.searcher.num_samples or 0)

    def trial_plan(self) -> list[dict[str, Any]]:
        """Every trial, in order: configurations x seeds.

        grid: the cartesian product of the grid values (YAML order, last key fastest), each a flat dict
        of dotted keys -> value plus ``seed``; the fixed ``config`` is not repeated (build_algorithm_config
        applies it). optuna: ``num_samples`` x seeds placeholders ``{"sample": i, "seed": s}``: the values
        are drawn by Optuna while the sweep runs (one study per seed).
        """
        if self.searcher.type == "grid" and self.seeds_per_trial > 1:
            return [
                {**point, keys.PLAN_SEEDS: group}
                for point in self.grid_points()
                for group in self.seed_groups()
            ]
        if self.searcher.type == "grid":
            return [{**point, "seed": seed} for point in self.grid_points() for seed in self.seeds]
        return [
            {"sample": i, "seed": seed} for seed in self.seeds for i in range(self.searcher.num_samples or 0)
        ]

    def budget(self) -> dict[str, Any]:
        n = len(self.trial_plan())
        waves = math.ceil(n / self.resources.max_concurrent_trials)
        return {
            "trials": n,
            "env_steps": None
            if self.stop.env_steps is None
            else n * self.seeds_per_trial * self.stop.env_steps,
            "iterations": None if self.stop.iterations is None else n * self.stop.iterations,
            "waves": waves,
            "cpus": self.resources.max_concurrent_trials * (self.resources.cpus_per_trial or 1),
        }


ParamSearch.model_rebuild()


def _point_label(point: Mapping[str, Any]) -> str:
    """A grid point as `key=value,...`, or `config` for the spec's fixed configuration alone."""
    return ",".join(f"{k}={v}" for k, v in sorted(point.items())) or "config"


def _all_params(params: Mapping[str, ParamSearch]) -> list[tuple[str, ParamSearch]]:
    out = []
    for key, ps in params.items():
        out.append((key, ps))
        for branch in (ps.when or {}).values():
            out.extend(_all_params(branch))
    return out


def _check_domain(key: str, ps: ParamSearch, setting: Setting, path: str) -> list[Issue]:
    """Every value a domain can produce must satisfy the key's own rule (ranges: both ends)."""
    d = ps.domain
    if d == "int" and setting.kind not in ("int", "float"):
        return [Issue(f"{path}.int", ps.values, f"{key} is not a number; use grid or categorical")]
    if d == "float" and setting.kind != "float":
        what = "an integer: use int" if setting.kind == "int" else "not a number; use grid or categorical"
        return [Issue(f"{path}.float", ps.values, f"{key} is {what}")]
    issues = []
    for i, value in enumerate(ps.values):
        if msg := rule_problem(key, setting, value):
            issues.append(Issue(f"{path}.{d}[{i}]", value, msg))
    return issues


def _representative_points(params: Mapping[str, ParamSearch]) -> list[dict[str, Any]]:
    """A few flat points of a sampled space: every branch of every conditional, ranges at both ends."""

    def expand(params: Mapping[str, ParamSearch], end: int) -> list[dict[str, Any]]:
        per_key: list[list[dict[str, Any]]] = []
        for key, ps in params.items():
            if ps.domain in ("int", "float"):
                per_key.append([{key: ps.values[end]}])
            elif ps.when:
                options = []
                for v in ps.values:
                    branch = ps.when.get(str(v), {})
                    options.extend({key: v, **sub} for sub in expand(branch, end))
                per_key.append(options)
            else:
                per_key.append([{key: ps.values[0]}])
        return [{k: v for d in combo for k, v in d.items()} for combo in itertools.product(*per_key)][:256]

    return expand(params, 0) + expand(params, 1)


def build_algorithm_config(flat: Mapping[str, Any], spec: SweepSpec) -> Any:
    """The RLlib algorithm config of one trial (a CoPilotConfig for ``algorithm: copilot``).

    ``flat`` is one trial's sampled values (dotted keys, e.g. from ``trial_plan()`` or Tune's config)
    plus optionally ``seed`` (default: the spec's first seed) and ``variant``; the spec's fixed
    ``config`` and the variant's keys are applied first and the trial's values override them. Imports
    RLlib.
    """
    entry = get_algorithm(spec.algorithm)
    variant = flat.get(keys.VARIANT_PARAM)
    if variant is not None and variant not in spec.variants:
        raise SpecError(
            [f"trial.variant: {variant!r} is invalid: the spec's variants are {list(spec.variants)}"]
        )
    env_id = flat.get(keys.ENV_PARAM, spec.env.ids[0])
    if env_id not in spec.env.ids:
        raise SpecError(
            [f"trial.{keys.ENV_PARAM}: {env_id!r} is invalid: the spec's envs are {spec.env.ids}"]
        )
    # (a stacked trial's plan names its seeds, `seeds`: its config is its first seed's)
    not_settings = (keys.SEED_PARAM, keys.PLAN_SEEDS, keys.VARIANT_PARAM, keys.ENV_PARAM)
    trial = {k: v for k, v in flat.items() if k not in not_settings}
    problems = [
        Issue(
            f"trial.{key}",
            value,
            f"unknown key{did_you_mean(key, entry.settings)}" if why == "unknown key" else f"{key} {why}",
        )
        for key, value, why in setting_problems(entry.settings, trial)
    ]
    if problems:
        raise SpecError([p.text() for p in problems])
    run = RunContext(
        env_id=env_id,
        env_config=dict(spec.env.config),
        seed=flat.get(keys.SEED_PARAM, (flat.get(keys.PLAN_SEEDS) or spec.seeds)[0]),
        num_env_runners=spec.resources.num_env_runners,
        num_cpus_for_main_process=spec.resources.cpus_per_trial - spec.resources.num_env_runners,
        num_gpus=spec.resources.gpus_per_trial,
        env_step_budget=spec.stop.env_steps,
    )
    return entry.build_config(spec.merged({k: v for k, v in flat.items() if k != keys.PLAN_SEEDS}), run)


def _test_metric_problem(metric: str, scheduler: SchedulerSpec | None) -> str:
    """Why a test-set metric cannot drive a search (or a scheduler), and what to use instead."""
    who = "the searcher" + (f" and the {scheduler.type} scheduler" if scheduler is not None else "")
    if metric.startswith(keys.EVAL_PREFIX):
        instead = f"use {keys.validation_key(metric)!r} (the same figure on the validation tasks)"
    else:
        instead = f"no validation figure is logged for it: use one of the {keys.VALIDATION_PREFIX}* metrics"
    return (
        f"is a test-set metric: {who} would choose by looking at the test tasks, which the report then "
        f"shows; {instead}"
    )


def rule_problem(key: str, setting: Setting, value: Any) -> str | None:
    """ "<key> must be <rule>" when `value` breaks the setting's rule, else None."""
    why = setting.problem(value)
    return None if why is None else f"{key} {why}"
