"""The sweep spec: a small YAML file, validated before anything starts, and the trial plan built from it.

    name: depth_k                       # required; also the folder under `tracking.storage`
    experiment: copilot-depth-k         # MLflow experiment (default: name)
    description: Fig. 2b, K = 1..6
    env: {id: maze-point, config: {layout: four-rooms}}
    algorithm: copilot                  # a key of ALGORITHMS
    config:                             # fixed overrides: flat, dotted keys (see COPILOT_KNOBS)
      repetitions: 5
      planner.std: 0.05
      alpha_schedule: paper_per_task    # a preset name or a mapping
    variants:                           # optional, grid only: named fixed overrides of `config`, one
      paper: {preset: paper_literal}    #   configuration each (an ablation: one reading per variant)
      restart: {after_failure: restart}
    search:                             # parameter -> one domain (same dotted keys as `config`)
      tree_depth: {grid: [1, 2, 3, 4, 5, 6]}
    seeds: [0, 1, 2]                    # every configuration runs once per seed
    searcher: {type: grid}              # or {type: optuna, sampler: tpe, metric: ..., mode: max, ...}
    scheduler: {type: asha, max_t: 200000, grace_period: 20000, reduction_factor: 3}   # optional
    stop: {env_steps: 200000}           # and/or iterations
    resources: {max_concurrent_trials: 2, num_env_runners: 0}   # cpus_per_trial >= 1 + num_env_runners
    tracking: {storage: results/}       # uri default: sqlite:///<abs storage>/<name>/mlflow.db

Search domains: ``{grid: [...]}``, ``{int: [low, high], log: false, step: 1}`` (both ends inclusive),
``{float: [low, high], log: false}`` (``step`` allowed when not log), ``{categorical: [...]}``. A
categorical domain may carry ``when: {choice: {param: domain, ...}}``: those parameters exist only in
trials that drew ``choice`` (they may nest). The alpha schedule is searched that way::

    alpha_schedule.kind:
      categorical: [constant, linear, exponential]
      when:
        constant: {alpha_schedule.alpha: {float: [0.0, 1.0]}}
        linear: {alpha_schedule.start: {float: [0.5, 1.0]}, alpha_schedule.end: {float: [0.0, 0.5]}}

Decisions (also in the report of the change that added this module):

* Strict types, no coercion: ``"5"`` is never an int, ``5.0`` is not an int, ``true`` is not a number;
  an int is accepted where a float is expected. YAML 1.1 reads ``1e-3`` as a *string*; the loader here
  resolves it as a float, as a reader expects. Duplicate YAML keys are an error (PyYAML silently keeps
  the last one).
* ``searcher: grid`` needs every domain to be ``grid``; ``optuna`` rejects ``grid`` (use
  ``categorical``): Tune's OptunaSearch cannot take ``tune.grid_search`` and a silent translation would
  hide that the sweep is no longer exhaustive. ``when`` is only allowed on ``categorical``, so grid sweeps
  stay a plain cartesian product (search whole ``alpha_schedule`` values to grid over schedules).
* Alpha schedule keys: ``alpha_schedule`` is a preset name or a full mapping; ``alpha_schedule.<field>``
  sets one field (the fields of ``copilot_ray.planning.alpha_schedule.AlphaSchedule``: kind, clock,
  alpha, start, end, duration, decay, boundaries, values). When ``alpha_schedule.kind`` is set (fixed or
  sampled), the schedule is built from the dotted fields alone; otherwise the dotted fields override
  ``alpha_schedule`` (or CoPilotConfig's default ``paper_per_task``). Setting both ``alpha_schedule`` and
  ``alpha_schedule.kind`` is rejected.
* ``variants`` are a grid axis of their own (trial param ``variant``): every variant runs every grid
  point and seed; a variant's keys override ``config`` and may not be searched. They exist because a
  cartesian grid cannot say "the defaults, and each reading back to the paper's one at a time".
* The searched space stays flat (ray issue 28753): a trial's parameters are a flat dict of dotted keys
  plus ``seed``; ``build_algorithm_config(flat, spec)`` turns it into the RLlib config.
* Optuna and seeds: Tune's searchers cannot repeat one sampled configuration over seeds, so an optuna
  sweep is ``len(seeds)`` studies of ``num_samples`` trials each (the sweep runner runs one Tuner per
  seed, sampler seed = ``searcher.seed + index``); ``trial_plan()`` returns placeholders for them.
* Nothing here imports Ray at module level; ``ray.tune`` is imported inside the ``to_tune_*`` functions
  only, and the CoPilotConfig import happens in ``build_algorithm_config``. A rejected spec has imported
  no Ray. Validation builds the env once (``copilot_ray.envs.make``), which imports numpy/torch.
* Relative ``tracking.storage`` is resolved against the working directory at load time (ARCHITECTURE.md, "Conventions": the
  default store lives in the working directory).
"""

from __future__ import annotations

import difflib
import itertools
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from copilot_ray.algorithms.copilot import readings
from copilot_ray.planning.planner import NOISE_MODES

__all__ = [
    "ALGORITHMS",
    "COPILOT_KNOBS",
    "COPILOT_METRICS",
    "TIME_ATTR",
    "AlgorithmEntry",
    "Knob",
    "ParamSearch",
    "SpecError",
    "SweepSpec",
    "build_algorithm_config",
    "load_spec",
    "load_yaml_value",
    "optuna_define_by_run",
    "parse_spec",
    "register_algorithm",
    "to_tune_scheduler",
    "to_tune_search_space",
    "tune_stop",
]

# Tune's time attribute for schedulers and stopping: environment steps (curves are per env step).
TIME_ATTR = "env_runners/num_env_steps_sampled_lifetime"
ITERATION_ATTR = "training_iteration"
MAX_TREE_DEPTH = 10
# What `alpha_schedule.*` dotted keys are built on when neither `alpha_schedule` nor `.kind` is given.
DEFAULT_ALPHA_PRESET = "paper_per_task"


class SpecError(ValueError):
    """A spec that cannot run. ``str(err)`` is one line per problem: ``file: key.path: value is invalid: why``."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


# ---------------------------------------------------------------------------------------------- problems
class _Issue(ValueError):
    """One problem found by a validator: path relative to where pydantic raised it (or absolute)."""

    def __init__(self, path: str, value: Any, reason: str, *, show_value: bool = True):
        self.path, self.value, self.reason, self.show_value = path, value, reason, show_value
        super().__init__(self.text())

    def text(self, prefix: str = "") -> str:
        path = _join(prefix, self.path)
        head = f"{path}: " if path else ""
        if self.show_value:
            return f"{head}{_short(self.value)} is invalid: {self.reason}"
        return f"{head}{self.reason}"


class _Issues(ValueError):
    def __init__(self, issues: list[_Issue]):
        self.issues = issues
        super().__init__("; ".join(i.text() for i in issues))


def _join(prefix: str, path: str) -> str:
    if not prefix:
        return path
    if not path:
        return prefix
    return prefix + path if path.startswith("[") else f"{prefix}.{path}"


def _short(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _did_you_mean(word: str, known: Iterable[str]) -> str:
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


# ---------------------------------------------------------------------------------------------- knobs
def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


@dataclass(frozen=True)
class Knob:
    """One settable key of an algorithm: its type, its rule, and where it goes in the algorithm config.

    kind: "int" | "float" | "bool" | "str" | "list" | "schedule" (what search domains it admits).
    target: the builder call and argument: "copilot" (``.copilot(key=...)``), "planner" / "cost_model"
    (``.copilot(planner={field: ...})``), "alpha_schedule" (one field of the schedule dict), "training"
    (``.training(key=...)``).
    """

    kind: str
    target: str
    check: Callable[[Any], bool]
    rule: str

    def problem(self, key: str, value: Any) -> str | None:
        try:
            ok = bool(self.check(value))
        except (TypeError, ValueError):
            ok = False
        return None if ok else f"{key} must be {self.rule}"


def _int(target: str, lo: int, hi: int | None = None, note: str = "") -> Knob:
    rule = f"an integer in [{lo}, {hi}]" if hi is not None else f"an integer >= {lo}"
    return Knob("int", target, lambda v: _is_int(v) and v >= lo and (hi is None or v <= hi), rule + note)


def _float(
    target: str, lo: float, hi: float | None = None, *, lo_open: bool = False, hi_open=False, optional=False
) -> Knob:
    """A number in a range; `optional`: null (None, "off") too."""

    def check(v: Any) -> bool:
        if v is None:
            return optional
        if not _is_num(v):
            return False
        above = v > lo if lo_open else v >= lo
        below = True if hi is None else (v < hi if hi_open else v <= hi)
        return above and below

    if hi is None:
        rule = f"a number {'>' if lo_open else '>='} {lo:g}"
    else:
        rule = f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    return Knob("float", target, check, rule + (" or null (off)" if optional else ""))


def _bool(target: str) -> Knob:
    return Knob("bool", target, lambda v: isinstance(v, bool), "true or false")


def _choice(target: str, choices: tuple[str, ...]) -> Knob:
    return Knob("str", target, lambda v: v in choices, f"one of {list(choices)}")


def _int_list(target: str) -> Knob:
    return Knob(
        "list",
        target,
        lambda v: isinstance(v, list) and len(v) > 0 and all(_is_int(x) and x >= 1 for x in v),
        "a non-empty list of integers >= 1 (hidden layer sizes)",
    )


def _num_list(target: str, lo: float | None = None, hi: float | None = None, what: str = "numbers") -> Knob:
    def check(v: Any) -> bool:
        return isinstance(v, list) and all(
            _is_num(x) and (lo is None or x >= lo) and (hi is None or x <= hi) for x in v
        )

    return Knob("list", target, check, f"a list of {what}")


def _alpha_schedule_ok(v: Any) -> bool:
    from copilot_ray.planning.alpha_schedule import AlphaSchedule

    if not isinstance(v, str | dict):
        return False
    AlphaSchedule.from_dict(v)  # raises ValueError naming the bad field
    return True


def _target_entropy_ok(v: Any) -> bool:
    return v == "auto" or _is_num(v)


_ALPHA_KINDS = ("constant", "linear", "exponential", "step")  # copilot_ray.planning.alpha_schedule.KINDS
_ALPHA_CLOCKS = ("global", "per_task")
_ALPHA_PRESETS = ("paper_warm_start", "paper_per_task", "euclidean", "time_cost")

# THE table of settable CO-PILOT keys (fixed `config` and `search` use the same names). `target` says how
# `build_algorithm_config` applies each one to a CoPilotConfig (copilot_ray/algorithms/copilot/config.py):
#   copilot        -> .copilot(<key>=value)
#   planner        -> .copilot(planner={<field>: value, ...})      (merged over DEFAULT_PLANNER)
#   cost_model     -> .copilot(cost_model={<field>: value, ...})   (merged over DEFAULT_COST_MODEL)
#   alpha_schedule -> .copilot(alpha_schedule=<dict assembled from alpha_schedule[.field] keys>)
#   training       -> .training(<key>=value)                       (SAC / AlgorithmConfig knobs)
COPILOT_KNOBS: dict[str, Knob] = {
    "tree_depth": _int(
        "copilot",
        0,
        MAX_TREE_DEPTH,
        " (0: no planner, plain goal-conditioned SAC; K > 10 is too deep for memory: 2^(K+1) - 1 sub-tasks per task)",
    ),
    "repetitions": _int("copilot", 1),
    "tau_max": _int("copilot", 1),
    "task_batch_size": _int("copilot", 1),
    "collision_penalty": _float("copilot", 0.0, optional=True),
    "collision_cost": _choice("copilot", ("indicator", "length")),  # planning.segment_cost.COLLISION_COSTS
    "updates_per_env_step": _float("copilot", 0.0, lo_open=True),
    "fast_learner": _bool("copilot"),
    "eval_interval": _int("copilot", 0, note=" (0: no evaluation)"),
    "eval_num_tasks": _int("copilot", 1),
    "eval_tree_tasks": _int("copilot", 0),
    "subtasks_per_sample": _int("copilot", 1),
    # Readings of the paper's ambiguities (copilot_ray/algorithms/copilot/readings.py); `preset` is
    # applied first, every other key of the spec overrides it.
    "preset": _choice("copilot", tuple(readings.PRESETS)),
    "step_limit": _choice("copilot", readings.STEP_LIMITS),
    "after_failure": _choice("copilot", readings.AFTER_FAILURE),
    "subtask_reward": _choice("copilot", readings.SUBTASK_REWARDS),
    "reward_scale": _float("copilot", 0.0, lo_open=True),
    "agent_collision": _choice("copilot", readings.AGENT_COLLISIONS),
    "agent_collision_penalty": _float("copilot", 0.0),
    "agent_input": _choice("copilot", readings.AGENT_INPUTS),
    "failed_subtask_cost": _choice("copilot", readings.FAILED_SUBTASK_COSTS),
    "traversal_tree": _choice("copilot", readings.TRAVERSAL_TREES),
    "planner_warm_start": _int("copilot", 0, note=" (planner phases before the first traversal)"),
    "planner_task_batch_size": _int("copilot", 1),
    "eval_action": _choice("copilot", readings.EVAL_ACTIONS),
    "alpha_schedule": Knob(
        "schedule",
        "alpha_schedule",
        _alpha_schedule_ok,
        f"a preset name {list(_ALPHA_PRESETS)} or a schedule mapping with kind in {list(_ALPHA_KINDS)}"
        " (to search over kinds use alpha_schedule.kind)",
    ),
    "alpha_schedule.kind": _choice("alpha_schedule", _ALPHA_KINDS),
    "alpha_schedule.clock": _choice("alpha_schedule", _ALPHA_CLOCKS),
    "alpha_schedule.alpha": _float("alpha_schedule", 0.0, 1.0),
    "alpha_schedule.start": _float("alpha_schedule", 0.0, 1.0),
    "alpha_schedule.end": _float("alpha_schedule", 0.0, 1.0),
    "alpha_schedule.duration": _float("alpha_schedule", 0.0, lo_open=True),
    "alpha_schedule.decay": _float("alpha_schedule", 0.0, 1.0, lo_open=True, hi_open=True),
    "alpha_schedule.boundaries": _num_list("alpha_schedule", what="numbers (increasing clock values)"),
    "alpha_schedule.values": _num_list("alpha_schedule", 0.0, 1.0, "alpha values in [0, 1]"),
    "planner.hidden": _int_list("planner"),
    "planner.std": _float("planner", 0.0, lo_open=True),
    "planner.noise": _choice("planner", NOISE_MODES),
    "planner.std_final": _float("planner", 0.0, lo_open=True, optional=True),
    "planner.std_anneal_phases": _int("planner", 1),
    "planner.lr": _float("planner", 0.0, lo_open=True),
    "planner.clip": _float("planner", 0.0, 1.0, lo_open=True, hi_open=True),
    "planner.epochs": _int("planner", 1),
    "planner.num_samples": _int("planner", 1),
    "planner.max_grad_norm": _float("planner", 0.0, lo_open=True, optional=True),
    "planner.target_kl": _float("planner", 0.0, lo_open=True, optional=True),
    "planner.max_kl": _float("planner", 0.0, lo_open=True, optional=True),
    "cost_model.hidden": _int_list("cost_model"),
    "cost_model.lr": _float("cost_model", 0.0, lo_open=True),
    "cost_model.capacity": _int("cost_model", 1),
    "cost_model.init_euclidean": _int("cost_model", 0),
    "cost_model.fit_steps": _int("cost_model", 1),
    "cost_model.batch_size": _int("cost_model", 1),
    "actor_lr": _float("training", 0.0, lo_open=True),
    "critic_lr": _float("training", 0.0, lo_open=True),
    "alpha_lr": _float("training", 0.0, lo_open=True),
    "gamma": _float("training", 0.0, 1.0, lo_open=True),
    # SAC's entropy temperature: its start value and the entropy it is tuned towards ("auto": -|A|).
    "initial_alpha": _float("training", 0.0, lo_open=True),
    "target_entropy": Knob("float", "training", _target_entropy_ok, '"auto" or a number'),
    "tau": _float("training", 0.0, 1.0, lo_open=True),
    "train_batch_size_per_learner": _int("training", 1),
    # RLlib's name for the update-to-data ratio (timesteps replayed per timestep sampled); an
    # alternative to updates_per_env_step = training_intensity / train_batch_size_per_learner.
    "training_intensity": _float("training", 0.0, lo_open=True),
    "num_steps_sampled_before_learning_starts": _int("training", 0),
}

# ARCHITECTURE.md "Metrics" plus RLlib's own; `<k>` is a tree layer (0..K).
COPILOT_METRICS: tuple[str, ...] = (
    "copilot/eval/success_planned",
    "copilot/eval/success_direct",
    "copilot/alpha",
    "copilot/planner/cost_layer_<k>",
    "copilot/planner/approx_kl_max",
    "copilot/planner/nonfinite_skipped",
    "copilot/agent/steps_layer_<k>",
    "copilot/agent/success_layer_<k>",
    "copilot/dtau/size",
    "copilot/cost_model/loss",
    "env_runners/num_env_steps_sampled_lifetime",
    "env_runners/episode_return_mean",
)


def _metric_known(metric: str, patterns: Iterable[str]) -> bool:
    for pattern in patterns:
        if "<k>" in pattern:
            regex = re.escape(pattern).replace(re.escape("<k>"), r"(\d+)")
            m = re.fullmatch(regex, metric)
            if m and int(m.group(1)) <= MAX_TREE_DEPTH:
                return True
        elif metric == pattern:
            return True
    return False


# ---------------------------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class AlgorithmEntry:
    """How a sweep builds one algorithm: ``build_config(flat, spec)``, the metrics it logs, its keys."""

    build_config: Callable[[dict[str, Any], SweepSpec], Any]
    metrics: tuple[str, ...]
    knobs: Mapping[str, Knob]


ALGORITHMS: dict[str, AlgorithmEntry] = {}


def register_algorithm(
    name: str,
    build_config: Callable[[dict[str, Any], SweepSpec], Any],
    metrics: Iterable[str],
    knobs: Mapping[str, Knob],
) -> None:
    """Make ``algorithm: <name>`` valid in specs (baselines call this when they land)."""
    ALGORITHMS[name] = AlgorithmEntry(build_config, tuple(metrics), dict(knobs))


def _alpha_schedule_from(flat: Mapping[str, Any]) -> Any:
    """The alpha schedule (preset name or dict) a flat trial dict asks for, or None for the default."""
    dotted = {k.split(".", 1)[1]: v for k, v in flat.items() if k.startswith("alpha_schedule.")}
    whole = flat.get("alpha_schedule")
    if not dotted:
        return whole
    if "kind" in dotted:
        return dotted
    from copilot_ray.planning.alpha_schedule import AlphaSchedule

    base = AlphaSchedule.from_dict(whole if whole is not None else DEFAULT_ALPHA_PRESET).to_dict()
    return {**base, **dotted}


def _build_copilot_config(flat: dict[str, Any], spec: SweepSpec) -> Any:
    from copilot_ray.algorithms.copilot import CoPilotConfig

    knobs = ALGORITHMS[spec.algorithm].knobs
    trial = {k: v for k, v in flat.items() if k not in ("seed", "variant")}
    variant = flat.get("variant")
    if variant is not None and variant not in spec.variants:
        raise SpecError(
            [f"trial.variant: {variant!r} is invalid: the spec's variants are {list(spec.variants)}"]
        )
    merged = spec.merged(flat)
    problems = [
        _Issue(f"trial.{k}", v, f"unknown key{_did_you_mean(k, knobs)}")
        for k, v in trial.items()
        if k not in knobs
    ]
    problems += [
        _Issue(f"trial.{k}", v, msg)
        for k, v in trial.items()
        if k in knobs and (msg := knobs[k].problem(k, v))
    ]
    if problems:
        raise SpecError([p.text() for p in problems])
    copilot: dict[str, Any] = {}
    training: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {"planner": {}, "cost_model": {}}
    for key, value in merged.items():
        target = knobs[key].target
        if target == "copilot":
            copilot[key] = value
        elif target in nested:
            nested[target][key.split(".", 1)[1]] = value
        elif target == "training":
            training[key] = value
    for name, fields in nested.items():
        if fields:
            copilot[name] = fields
    schedule = _alpha_schedule_from(merged)
    if schedule is not None:
        copilot["alpha_schedule"] = schedule
    seed = flat.get("seed", spec.seeds[0])
    config = (
        CoPilotConfig()
        .environment(spec.env.id, env_config=dict(spec.env.config))
        .env_runners(num_env_runners=spec.resources.num_env_runners)
        # The trial's own process (sampling when there are no runners, and the learner) gets the CPUs
        # not taken by runners; CoPilotConfig sizes torch's thread pool from it.
        .resources(num_cpus_for_main_process=spec.resources.cpus_per_trial - spec.resources.num_env_runners)
        .debugging(seed=seed)
        .copilot(**copilot)
    )
    if training:
        config.training(**training)
    return config


register_algorithm("copilot", _build_copilot_config, COPILOT_METRICS, COPILOT_KNOBS)


def build_algorithm_config(flat: dict[str, Any], spec: SweepSpec) -> Any:
    """The algorithm config (a CoPilotConfig for ``algorithm: copilot``) of one trial.

    ``flat`` is one trial's sampled values (dotted keys, e.g. from ``trial_plan()`` or Tune's config)
    plus optionally ``seed`` (default: the spec's first seed); the spec's fixed ``config`` is applied
    first and the trial's values override it. Imports RLlib.
    """
    return ALGORITHMS[spec.algorithm].build_config(dict(flat), spec)


# ---------------------------------------------------------------------------------------------- models
class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, populate_by_name=False)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            known = [f.alias or n for n, f in cls.model_fields.items()]
            unknown = [k for k in data if k not in known]
            if unknown:
                raise _Issues(
                    [
                        _Issue(
                            str(k),
                            data[k],
                            f"unknown key{_did_you_mean(str(k), known)} (known keys: {', '.join(known)})",
                            show_value=False,
                        )
                        for k in unknown
                    ]
                )
        return data


class ParamSearch(_Model):
    """One searched parameter: exactly one of grid / int / float / categorical."""

    grid: list[Any] | None = None
    int_: list[int] | None = Field(default=None, alias="int")
    float_: list[float] | None = Field(default=None, alias="float")
    categorical: list[Any] | None = None
    log: bool = False
    step: int | float | None = None
    when: dict[str, dict[str, ParamSearch]] | None = None

    @property
    def domain(self) -> str:
        for name in ("grid", "int", "float", "categorical"):
            if self.values_of(name) is not None:
                return name
        raise AssertionError("validated ParamSearch has a domain")

    def values_of(self, name: str) -> list[Any] | None:
        return {"grid": self.grid, "int": self.int_, "float": self.float_, "categorical": self.categorical}[
            name
        ]

    @property
    def values(self) -> list[Any]:
        return list(self.values_of(self.domain) or [])

    @model_validator(mode="after")
    def _one_domain(self) -> ParamSearch:
        given = [n for n in ("grid", "int", "float", "categorical") if self.values_of(n) is not None]
        if len(given) != 1:
            raise _Issue(
                "",
                None,
                "give exactly one of grid, int, float, categorical"
                + (f" (got {', '.join(given)})" if given else ""),
                show_value=False,
            )
        domain = given[0]
        values = self.values_of(domain)
        issues: list[_Issue] = []
        if domain in ("grid", "categorical"):
            if not values:
                issues.append(
                    _Issue(domain, values, f"an empty {domain} has nothing to run; list >= 1 value")
                )
            dupes = [v for i, v in enumerate(values) if v in values[:i]]
            if dupes:
                issues.append(_Issue(domain, values, f"duplicate value {dupes[0]!r} would run twice"))
            if self.log or self.step is not None:
                issues.append(_Issue(domain, values, "log and step apply to int and float ranges only"))
        else:
            if len(values) != 2:
                issues.append(_Issue(domain, values, f"{domain} takes [low, high]"))
            else:
                low, high = values
                if low > high:
                    issues.append(_Issue(domain, values, f"low {low!r} > high {high!r}"))
                if self.log and low <= 0:
                    issues.append(_Issue(domain, values, f"a log range needs low > 0, got low {low!r}"))
            if self.step is not None:
                if domain == "int" and not (_is_int(self.step) and self.step >= 1):
                    issues.append(_Issue("step", self.step, "an int range's step must be an integer >= 1"))
                if domain == "float" and not (_is_num(self.step) and self.step > 0):
                    issues.append(_Issue("step", self.step, "step must be a number > 0"))
                if self.log and self.step != 1 and domain == "int" or self.log and domain == "float":
                    issues.append(_Issue("step", self.step, "log ranges cannot have a step (Optuna)"))
        if self.when is not None:
            if domain != "categorical":
                issues.append(
                    _Issue("when", None, "conditional parameters need a categorical domain", show_value=False)
                )
            else:
                labels = [str(v) for v in values]
                for choice in self.when:
                    if choice not in labels:
                        issues.append(
                            _Issue(
                                f"when.{choice}",
                                choice,
                                f"not one of the categorical values {labels}{_did_you_mean(choice, labels)}",
                            )
                        )
        if issues:
            raise _Issues(issues)
        return self

    def describe(self) -> str:
        d = self.domain
        if d in ("grid", "categorical"):
            return f"{d} {self.values}"
        extra = (" log" if self.log else "") + (f" step {self.step}" if self.step is not None else "")
        return f"{d} [{self.values[0]}, {self.values[1]}]{extra}"


class EnvSpec(_Model):
    id: str
    config: dict[str, Any] = Field(default_factory=dict)


class SearcherSpec(_Model):
    type: Literal["grid", "optuna"] = "grid"
    sampler: Literal["tpe", "random", "cmaes"] | None = None
    metric: str | None = None
    mode: Literal["max", "min"] | None = None
    num_samples: int | None = None
    seed: int | None = None

    @model_validator(mode="after")
    def _per_type(self) -> SearcherSpec:
        issues = []
        if self.type == "grid":
            for key in ("sampler", "num_samples", "seed"):
                if getattr(self, key) is not None:
                    issues.append(_Issue(key, getattr(self, key), "only an optuna searcher takes it"))
        else:
            self.sampler = self.sampler or "tpe"
            if self.metric is None:
                issues.append(_Issue("metric", None, "an optuna searcher needs the metric it optimises"))
            if self.mode is None:
                issues.append(_Issue("mode", None, "an optuna searcher needs mode: max or min"))
            if self.num_samples is None or self.num_samples < 1:
                issues.append(_Issue("num_samples", self.num_samples, "must be an integer >= 1"))
            if self.seed is None:
                self.seed = 0
        if (self.metric is None) != (self.mode is None) and self.type == "grid":
            issues.append(
                _Issue("mode" if self.mode is None else "metric", None, "give metric and mode together")
            )
        if issues:
            raise _Issues(issues)
        return self


class SchedulerSpec(_Model):
    """Early stopping under Tune; time is measured in environment steps (TIME_ATTR)."""

    type: Literal["asha", "median_stopping"]
    max_t: int | None = None
    grace_period: int | None = None
    reduction_factor: float | None = None
    min_samples_required: int | None = None

    @model_validator(mode="after")
    def _per_type(self) -> SchedulerSpec:
        issues = []
        own = {
            "asha": ("max_t", "grace_period", "reduction_factor"),
            "median_stopping": ("grace_period", "min_samples_required"),
        }
        for key in ("max_t", "grace_period", "reduction_factor", "min_samples_required"):
            if key not in own[self.type] and getattr(self, key) is not None:
                issues.append(_Issue(key, getattr(self, key), f"does not apply to type {self.type}"))
        if self.type == "asha":
            if self.max_t is None or self.max_t < 1:
                issues.append(_Issue("max_t", self.max_t, "ASHA needs max_t >= 1 (environment steps)"))
            self.grace_period = 1 if self.grace_period is None else self.grace_period
            self.reduction_factor = 3.0 if self.reduction_factor is None else self.reduction_factor
            if self.reduction_factor <= 1:
                issues.append(_Issue("reduction_factor", self.reduction_factor, "must be > 1"))
        else:
            self.grace_period = 1 if self.grace_period is None else self.grace_period
            self.min_samples_required = 3 if self.min_samples_required is None else self.min_samples_required
            if self.min_samples_required < 1:
                issues.append(_Issue("min_samples_required", self.min_samples_required, "must be >= 1"))
        if self.grace_period < 1:
            issues.append(_Issue("grace_period", self.grace_period, "must be >= 1 (environment steps)"))
        elif self.max_t is not None and self.max_t >= 1 and self.grace_period > self.max_t:
            issues.append(_Issue("grace_period", self.grace_period, f"must be <= max_t ({self.max_t})"))
        if issues:
            raise _Issues(issues)
        return self


class StopSpec(_Model):
    env_steps: int | None = None
    iterations: int | None = None

    @model_validator(mode="after")
    def _one(self) -> StopSpec:
        if self.env_steps is None and self.iterations is None:
            raise _Issue("", None, "give env_steps and/or iterations", show_value=False)
        issues = [
            _Issue(k, getattr(self, k), "must be an integer >= 1")
            for k in ("env_steps", "iterations")
            if getattr(self, k) is not None and getattr(self, k) < 1
        ]
        if issues:
            raise _Issues(issues)
        return self


class ResourcesSpec(_Model):
    max_concurrent_trials: int = 1
    num_env_runners: int = 0
    cpus_per_trial: int | None = None

    @model_validator(mode="after")
    def _sizes(self) -> ResourcesSpec:
        issues = []
        if self.max_concurrent_trials < 1:
            issues.append(_Issue("max_concurrent_trials", self.max_concurrent_trials, "must be >= 1"))
        if self.num_env_runners < 0:
            issues.append(_Issue("num_env_runners", self.num_env_runners, "must be >= 0"))
        need = 1 + max(self.num_env_runners, 0)
        if self.cpus_per_trial is None:
            self.cpus_per_trial = need
        elif self.cpus_per_trial < need:
            issues.append(
                _Issue(
                    "cpus_per_trial",
                    self.cpus_per_trial,
                    f"a trial needs 1 CPU for its driver + 1 per env runner = {need}",
                )
            )
        if issues:
            raise _Issues(issues)
        return self


class TrackingSpec(_Model):
    uri: str | None = None
    storage: str = "results/"


class SweepSpec(_Model):
    name: str
    experiment: str | None = None
    description: str | None = None
    env: EnvSpec
    algorithm: str = "copilot"
    config: dict[str, Any] = Field(default_factory=dict)
    variants: dict[str, dict[str, Any]] = Field(default_factory=dict)
    search: dict[str, ParamSearch] = Field(default_factory=dict)
    seeds: list[int] = Field(default_factory=lambda: [0])
    searcher: SearcherSpec = Field(default_factory=SearcherSpec)
    scheduler: SchedulerSpec | None = None
    stop: StopSpec
    resources: ResourcesSpec = Field(default_factory=ResourcesSpec)
    tracking: TrackingSpec = Field(default_factory=TrackingSpec)

    _source: str = PrivateAttr(default="<spec>")

    # ------------------------------------------------------------------ validation across sections
    @model_validator(mode="after")
    def _check(self) -> SweepSpec:
        issues: list[_Issue] = []
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", self.name):
            issues.append(_Issue("name", self.name, "use letters, digits, '_', '-', '.' (it names a folder)"))
        self.experiment = self.experiment or self.name
        if self.algorithm not in ALGORITHMS:
            issues.append(
                _Issue(
                    "algorithm",
                    self.algorithm,
                    f"unknown algorithm{_did_you_mean(self.algorithm, ALGORITHMS)}; known: {sorted(ALGORITHMS)}",
                )
            )
            raise _Issues(issues)
        entry = ALGORITHMS[self.algorithm]
        issues += self._check_env()
        issues += self._check_config(entry.knobs)
        issues += self._check_variants(entry.knobs)
        issues += self._check_search(entry.knobs)
        issues += self._check_seeds()
        issues += self._check_searcher(entry)
        if not issues:
            issues += self._check_combinations(entry.knobs)
        storage = Path(self.tracking.storage).expanduser().resolve()
        self.tracking.storage = str(storage)
        if self.tracking.uri is None:
            self.tracking.uri = f"sqlite:///{storage / self.name / 'mlflow.db'}"
        if issues:
            raise _Issues(issues)
        return self

    def _check_env(self) -> list[_Issue]:
        from copilot_ray.envs import env_ids, make

        ids = env_ids()
        if self.env.id not in ids:
            return [
                _Issue(
                    "env.id", self.env.id, f"unknown env id{_did_you_mean(self.env.id, ids)}; known: {ids}"
                )
            ]
        try:
            make(self.env.id, **self.env.config).close()
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
            elif type(err).__name__ == "LayoutError" and "layout" in self.env.config:
                path = "env.config.layout"
            value = self.env.config.get(path[len("env.config.") :], self.env.config)
            return [_Issue(path, value, f"building env {self.env.id!r} failed: {type(err).__name__}: {text}")]
        return []

    def _check_config(self, knobs: Mapping[str, Knob]) -> list[_Issue]:
        issues = []
        for key, value in self.config.items():
            if key not in knobs:
                issues.append(
                    _Issue(
                        f"config.{key}",
                        value,
                        f"unknown key{_did_you_mean(key, knobs)} (known keys: see COPILOT_KNOBS in copilot_ray/spec.py)",
                        show_value=False,
                    )
                )
            elif msg := knobs[key].problem(key, value):
                issues.append(_Issue(f"config.{key}", value, msg))
        if "seed" in self.config:
            issues.append(
                _Issue("config.seed", self.config["seed"], "seeds are set by the top-level `seeds` list")
            )
        if "alpha_schedule" in self.config and "alpha_schedule.kind" in self.config:
            issues.append(
                _Issue(
                    "config.alpha_schedule.kind",
                    self.config["alpha_schedule.kind"],
                    "give either alpha_schedule (preset or mapping) or alpha_schedule.kind with its fields, not both",
                )
            )
        return issues

    def _check_variants(self, knobs: Mapping[str, Knob]) -> list[_Issue]:
        issues = []
        if self.variants and self.searcher.type != "grid":
            issues.append(_Issue("variants", list(self.variants), "variants need searcher type: grid"))
        for name, overrides in self.variants.items():
            if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
                issues.append(_Issue(f"variants.{name}", name, "use letters, digits, '_', '-', '.'"))
            if not isinstance(overrides, dict):
                issues.append(_Issue(f"variants.{name}", overrides, "must be a mapping of config keys"))
                continue
            for key, value in overrides.items():
                path = f"variants.{name}.{key}"
                if key not in knobs:
                    issues.append(
                        _Issue(path, value, f"unknown key{_did_you_mean(key, knobs)}", show_value=False)
                    )
                elif msg := knobs[key].problem(key, value):
                    issues.append(_Issue(path, value, msg))
                elif key in self.search:
                    issues.append(_Issue(path, value, f"{key} is also searched; keep one"))
        return issues

    def _check_search(self, knobs: Mapping[str, Knob]) -> list[_Issue]:
        issues: list[_Issue] = []
        seen: dict[str, str] = {}

        def walk(params: Mapping[str, ParamSearch], prefix: str, fixed_here: set[str]) -> None:
            for key, ps in params.items():
                path = f"{prefix}.{key}"
                if key not in knobs:
                    issues.append(
                        _Issue(path, key, f"unknown key{_did_you_mean(key, knobs)}", show_value=False)
                    )
                    continue
                if key in self.config:
                    issues.append(
                        _Issue(path, key, f"{key} is also fixed in config; keep one", show_value=False)
                    )
                if key in fixed_here:
                    issues.append(
                        _Issue(path, key, f"{key} is already searched at {seen[key]}", show_value=False)
                    )
                seen.setdefault(key, path)
                issues.extend(_check_domain(key, ps, knobs[key], path))
                if ps.when:
                    for choice, branch in ps.when.items():
                        walk(branch, f"{path}.when.{choice}", fixed_here | set(params))
                if key == "alpha_schedule.kind" and (
                    "alpha_schedule" in self.config or "alpha_schedule" in self.search
                ):
                    issues.append(
                        _Issue(
                            path,
                            key,
                            "searching alpha_schedule.kind excludes alpha_schedule",
                            show_value=False,
                        )
                    )

        walk(self.search, "search", set())
        return issues

    def _check_seeds(self) -> list[_Issue]:
        if not self.seeds:
            return [_Issue("seeds", self.seeds, "list at least one seed")]
        issues = [_Issue(f"seeds[{i}]", s, "seeds must be >= 0") for i, s in enumerate(self.seeds) if s < 0]
        dupes = [s for i, s in enumerate(self.seeds) if s in self.seeds[:i]]
        if dupes:
            issues.append(
                _Issue("seeds", self.seeds, f"duplicate seed {dupes[0]} would run the same trial twice")
            )
        return issues

    def _check_searcher(self, entry: AlgorithmEntry) -> list[_Issue]:
        issues = []
        s = self.searcher
        for path, metric in (("searcher.metric", s.metric),):
            if metric is not None and not _metric_known(metric, entry.metrics):
                names = [m.replace("<k>", "0") for m in entry.metrics]
                issues.append(
                    _Issue(
                        path,
                        metric,
                        f"{self.algorithm} does not log this metric{_did_you_mean(metric, names)}; "
                        f"it logs {list(entry.metrics)}",
                    )
                )
        for key, ps in _all_params(self.search):
            if s.type == "grid" and ps.domain != "grid":
                issues.append(
                    _Issue(f"search.{key}", ps.domain, "a grid searcher needs every domain to be grid")
                )
            if s.type == "optuna" and ps.domain == "grid":
                issues.append(
                    _Issue(
                        f"search.{key}",
                        "grid",
                        "an optuna searcher samples; use categorical (or searcher type: grid)",
                    )
                )
        if s.type == "optuna" and not self.search:
            issues.append(_Issue("search", {}, "an optuna searcher needs at least one searched parameter"))
        if self.scheduler is not None and s.metric is None:
            issues.append(
                _Issue(
                    "scheduler", self.scheduler.type, "a scheduler needs searcher.metric and searcher.mode"
                )
            )
        return issues

    def _check_combinations(self, knobs: Mapping[str, Knob]) -> list[_Issue]:
        """Keys valid one by one can clash together (an alpha schedule missing a field): try them."""
        from copilot_ray.planning.alpha_schedule import AlphaSchedule

        issues = []
        points = self._grid_points() if self.searcher.type == "grid" else _representative_points(self.search)
        for point in points:
            merged = self.merged(point)
            if "updates_per_env_step" in merged and "training_intensity" in merged:
                where = "search" if {"updates_per_env_step", "training_intensity"} & set(point) else "config"
                both = {k: merged[k] for k in ("updates_per_env_step", "training_intensity")}
                issues.append(_Issue(where, both, "both set the update-to-data ratio; set one"))
                break
        for point in points:
            merged = self.merged(point)
            if not any(k.startswith("alpha_schedule") for k in merged):
                continue
            try:
                schedule = _alpha_schedule_from(merged)
                AlphaSchedule.from_dict(schedule)
            except (ValueError, TypeError) as err:
                where = "search" if any(k.startswith("alpha_schedule") for k in point) else "config"
                keys = {k: v for k, v in merged.items() if k.startswith("alpha_schedule")}
                issues.append(_Issue(where, keys, f"these alpha_schedule keys do not form a schedule: {err}"))
                break
        return issues

    # ------------------------------------------------------------------ the plan
    @property
    def source(self) -> str:
        return self._source

    @property
    def searched_keys(self) -> list[str]:
        return [k for k, _ in _all_params(self.search)]

    @property
    def has_conditional_params(self) -> bool:
        return any(ps.when for _, ps in _all_params(self.search))

    def _grid_points(self) -> list[dict[str, Any]]:
        keys = list(self.search)
        values = [self.search[k].values for k in keys]
        points = [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*values)]
        return self._with_variants(points)

    def _with_variants(self, points: list[dict[str, Any]]) -> list[dict[str, Any]]:
        if not self.variants:
            return points
        return [
            {"variant": name, **p} for name in self.variants for p in points if "variant" not in p
        ] or points

    def merged(self, point: Mapping[str, Any]) -> dict[str, Any]:
        """A trial's effective fixed keys: ``config``, its variant's overrides, then its own values."""
        rest = {k: v for k, v in point.items() if k not in ("variant", "seed")}
        return {**self.config, **self.variants.get(point.get("variant"), {}), **rest}

    def num_configurations(self) -> int:
        if self.searcher.type == "grid":
            return max(1, len(self.variants)) * math.prod(len(ps.values) for ps in self.search.values())
        return int(self.searcher.num_samples or 0)

    def trial_plan(self) -> list[dict[str, Any]]:
        """Every trial, in order: configurations x seeds.

        grid: the cartesian product of the grid values (YAML order, last key fastest), each a flat dict
        of dotted keys -> value plus ``seed``; the fixed ``config`` is not repeated (build_algorithm_config
        applies it). optuna: ``num_samples`` x seeds placeholders ``{"sample": i, "seed": s}``: the values
        are drawn by Optuna while the sweep runs (one study per seed).
        """
        if self.searcher.type == "grid":
            return [{**point, "seed": seed} for point in self._grid_points() for seed in self.seeds]
        return [
            {"sample": i, "seed": seed} for seed in self.seeds for i in range(self.searcher.num_samples or 0)
        ]

    def budget(self) -> dict[str, Any]:
        n = len(self.trial_plan())
        waves = math.ceil(n / self.resources.max_concurrent_trials)
        return {
            "trials": n,
            "env_steps": None if self.stop.env_steps is None else n * self.stop.env_steps,
            "iterations": None if self.stop.iterations is None else n * self.stop.iterations,
            "waves": waves,
            "cpus": self.resources.max_concurrent_trials * (self.resources.cpus_per_trial or 1),
        }

    def format_plan(self) -> str:
        """A readable summary for ``--check``: what runs, how many trials, the budget."""
        lines = [
            f"sweep {self.name!r} ({self.source}): {self.algorithm} on {self.env.id} {self.env.config or ''}"
        ]
        if self.description:
            lines.append(f"  {self.description.strip()}")
        lines.append(f"  MLflow experiment {self.experiment!r} at {self.tracking.uri}")
        if self.config:
            lines.append("  fixed: " + ", ".join(f"{k}={v!r}" for k, v in self.config.items()))
        for name, overrides in self.variants.items():
            text = ", ".join(f"{k}={v!r}" for k, v in overrides.items()) or "(config as it is)"
            lines.append(f"  variant {name}: {text}")
        seeds = ", ".join(str(s) for s in self.seeds)
        if self.searcher.type == "grid":
            points = self._grid_points()
            keys = (["variant"] if self.variants else []) + list(self.search)
            header = ["#", *keys, "seeds"]
            rows = [[str(i + 1), *(_cell(p[k]) for k in keys), seeds] for i, p in enumerate(points)]
            widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]
            lines.append(f"  grid: {len(points)} configuration(s) x {len(self.seeds)} seed(s)")
            for row in [header, *rows]:
                lines.append(
                    "    " + "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
                )
        else:
            s = self.searcher
            lines.append(
                f"  optuna {s.sampler}: {s.mode} {s.metric}, {s.num_samples} sample(s) per seed, "
                f"seeds [{seeds}] (one study per seed, sampler seed {s.seed} + index)"
            )
            lines.extend(_describe_space(self.search, "    "))
        if self.scheduler is not None:
            sch = self.scheduler
            args = {k: v for k, v in sch.model_dump().items() if k != "type" and v is not None}
            lines.append(f"  scheduler: {sch.type} on {TIME_ATTR} {args}")
        b = self.budget()
        stop = " and ".join(
            t
            for t in (
                f"{self.stop.env_steps} env steps" if self.stop.env_steps else "",
                f"{self.stop.iterations} iterations" if self.stop.iterations else "",
            )
            if t
        )
        lines.append(
            f"  {b['trials']} trial(s), each stops at {stop}; "
            + (f"at most {b['env_steps']:,} env steps in all; " if b["env_steps"] else "")
            + f"{self.resources.max_concurrent_trials} at a time ({b['waves']} wave(s)), "
            f"{self.resources.cpus_per_trial} CPU(s) per trial, {b['cpus']} CPU(s) in use"
        )
        return "\n".join(lines)


ParamSearch.model_rebuild()


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


def _all_params(params: Mapping[str, ParamSearch]) -> list[tuple[str, ParamSearch]]:
    out = []
    for key, ps in params.items():
        out.append((key, ps))
        for branch in (ps.when or {}).values():
            out.extend(_all_params(branch))
    return out


def _check_domain(key: str, ps: ParamSearch, knob: Knob, path: str) -> list[_Issue]:
    """Every value a domain can produce must satisfy the key's own rule (ranges: both ends)."""
    d = ps.domain
    if d == "int" and knob.kind not in ("int", "float"):
        return [_Issue(f"{path}.int", ps.values, f"{key} is not a number; use grid or categorical")]
    if d == "float" and knob.kind != "float":
        what = "an integer: use int" if knob.kind == "int" else "not a number; use grid or categorical"
        return [_Issue(f"{path}.float", ps.values, f"{key} is {what}")]
    issues = []
    for i, value in enumerate(ps.values):
        if msg := knob.problem(key, value):
            issues.append(_Issue(f"{path}.{d}[{i}]", value, msg))
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


# ---------------------------------------------------------------------------------------------- YAML
class _SpecLoader(yaml.SafeLoader):
    """SafeLoader + `1e-3` is a float (YAML 1.1 reads it as a string) + duplicate keys are errors."""

    def construct_mapping(self, node, deep=False):  # noqa: ANN001 - PyYAML's signature
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                mark = key_node.start_mark
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first at line {seen[key] + 1})", mark
                )
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


_SpecLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+][0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def _format_validation_error(err: ValidationError, source: str) -> list[str]:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in e["loc"]).replace(".[", "[")
        exc = (e.get("ctx") or {}).get("error")
        if isinstance(exc, _Issues):
            lines += [f"{source}: {i.text(loc)}" for i in exc.issues]
        elif isinstance(exc, _Issue):
            lines.append(f"{source}: {exc.text(loc)}")
        elif e["type"] == "missing":
            lines.append(f"{source}: {loc}: required key is missing")
        else:
            lines.append(f"{source}: {loc}: {_short(e.get('input'))} is invalid: {e['msg']}")
    return lines


def load_yaml_value(text: str) -> Any:
    """One value written as in a spec (YAML, with ``1e-3`` read as a float, as a reader expects)."""
    return yaml.load(text, Loader=_SpecLoader)  # noqa: S506 - a SafeLoader subclass


def parse_spec(data: Any, source: str = "<spec>") -> SweepSpec:
    """Validate an already-parsed spec (a mapping); raises SpecError naming ``source``."""
    if not isinstance(data, dict):
        raise SpecError(
            [f"{source}: the spec must be a mapping of keys (name, env, ...), got {_short(data)}"]
        )
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as err:
        raise SpecError(_format_validation_error(err, source)) from None
    spec._source = source
    return spec


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep YAML file; raises SpecError (a ValueError) naming file, key path, value."""
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise SpecError([f"{source}: cannot read the spec: {err.strerror or err}"]) from None
    try:
        data = yaml.load(text, Loader=_SpecLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark is not None else source
        problem = getattr(err, "problem", None) or str(err)
        raise SpecError([f"{where}: YAML syntax error: {problem}"]) from None
    return parse_spec(data, source)


# ---------------------------------------------------------------------------------------------- Tune
def tune_stop(spec: SweepSpec) -> dict[str, int]:
    """Tune's ``stop`` criteria (either one ends a trial)."""
    stop = {}
    if spec.stop.env_steps is not None:
        stop[TIME_ATTR] = spec.stop.env_steps
    if spec.stop.iterations is not None:
        stop[ITERATION_ATTR] = spec.stop.iterations
    return stop


def to_tune_search_space(spec: SweepSpec) -> dict[str, Any]:
    """The flat Tune ``param_space`` of the searched keys (dotted names; imports ray.tune).

    grid -> ``tune.grid_search`` (plus ``seed: tune.grid_search(seeds)``); int -> ``randint`` /
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
        space["variant"] = tune.grid_search(list(spec.variants))
    if spec.searcher.type == "grid":
        space["seed"] = tune.grid_search(list(spec.seeds))
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

    common = {"time_attr": TIME_ATTR, "metric": spec.searcher.metric, "mode": spec.searcher.mode}
    if sch.type == "asha":
        return ASHAScheduler(
            max_t=sch.max_t, grace_period=sch.grace_period, reduction_factor=sch.reduction_factor, **common
        )
    return MedianStoppingRule(
        grace_period=sch.grace_period, min_samples_required=sch.min_samples_required, **common
    )
