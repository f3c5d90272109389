"""Algorithm names -> where they are declared. A new algorithm is one module plus one line in
ALGORITHMS (or one `register_algorithm` call).

A line names three things: "settings_module", "module:ConfigClass" and "module:TrialClass" (one module
may hold all three).
The settings module must import without Ray (sweep specs are validated against it before anything
starts) and provide:

    SETTINGS: dict[str, Setting]          every key a spec's config/search/variants, the train CLI and
                                          benchmarks' --set accept (copilot_ray.settings.Setting)
    METRICS: tuple[str, ...]              what it logs that a sweep may optimise (`<k>`: a tree layer)
    combination_problems(values)          optional: [(keys, value, why)] for values that clash together
    max_iteration_env_steps(values)       optional: the most env steps one iteration can take (--check's
                                          evaluations per trial); none for an algorithm without env steps
    max_env_steps_past_budget(values)     optional: the most env steps a run can take past its env-step
                                          budget (RunContext.env_step_budget) or an evaluation point, for an
                                          algorithm that ends iterations early there (at a repetition);
                                          default: one iteration's less 1
    SEARCH_SPACE: dict[str, dict]         optional: what a comparison tunes (`search: declared` in a spec),
                                          in the spec's domain syntax, every default inside its range
    PRIVILEGES: tuple[str, ...]           optional: what the method always uses that agents learning from
                                          their own episodes do not (copilot_ray.privileges); a setting
                                          whose value grants more says so itself (Setting.grants)
    GPU_LEARNER: bool                     optional: its learner runs on a GPU when a spec gives trials
                                          one (resources.gpus_per_trial; RLlib places it); default False
    SEED_STACK: bool                      optional: several seeds can share one trial, their SAC updates
                                          stacked (a spec's seeds_per_trial; a GoalSAC agent with the
                                          fused update); default False
    PRESETS: dict[str, dict]              optional: named sets of values (`preset: <name>`)
    as_logged(values)                     optional: effective flat values -> the settings as its runs'
                                          params hold them, where a setting is logged as other keys
                                          (CO-PILOT's alpha schedule as its fields); default: as they are

The config class (an RLlib AlgorithmConfig, imported only when a run is built) provides
`from_settings(values, run)`: flat setting values + a RunContext -> a config ready to build. The trial
class is what a sweep runs: `class MyTrial(trials.spec_trial.SpecTrial, MyAlgorithm)` for an RLlib Algorithm,
or a Tune Trainable (`copilot_ray.trials.planning_trial.PlanningTrial` for the planner-only baselines,
whose config class is a plain dataclass).
"""

from __future__ import annotations

import difflib
import importlib
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from copilot_ray.privileges import privileges_of
from copilot_ray.settings import MAX_TREE_DEPTH, Setting, effective, logged_text

ALGORITHMS: dict[str, tuple[str, str, str]] = {
    "copilot": (
        "copilot_ray.algorithms.copilot.settings",
        "copilot_ray.algorithms.copilot.algorithm:CoPilotConfig",
        "copilot_ray.algorithms.copilot.trial:CoPilotTrial",
    ),
    # The agent-only baselines (CO-PILOT's agent at tree depth 0): SAC, and SAC with HER's replay.
    "sac": (
        "copilot_ray.algorithms.sac.settings",
        "copilot_ray.algorithms.sac.algorithm:GoalSACConfig",
        "copilot_ray.algorithms.sac.trial:GoalSACTrial",
    ),
    "her": (
        "copilot_ray.algorithms.sac.her_settings",
        "copilot_ray.algorithms.sac.algorithm:HERConfig",
        "copilot_ray.algorithms.sac.trial:GoalSACTrial",
    ),
    "sorb": (
        "copilot_ray.algorithms.sorb.settings",
        "copilot_ray.algorithms.sorb.algorithm:SoRBConfig",
        "copilot_ray.algorithms.sorb.trial:SoRBTrial",
    ),
    # SoRB with the map: its graph keeps only edges the map finds free (CO-PILOT's map access, counted).
    "sorb_map": (
        "copilot_ray.algorithms.sorb_map.settings",
        "copilot_ray.algorithms.sorb.algorithm:SoRBMapConfig",
        "copilot_ray.algorithms.sorb.trial:SoRBTrial",
    ),
    "ppo": (
        "copilot_ray.algorithms.ppo.settings",
        "copilot_ray.algorithms.ppo.algorithm:GoalPPOConfig",
        "copilot_ray.algorithms.ppo.trial:GoalPPOTrial",
    ),
    # CO-PILOT's traversal and agent on trees cut from RRT* paths: a curriculum with no learned planner.
    "rrt_curriculum": (
        "copilot_ray.algorithms.rrt_curriculum.settings",
        "copilot_ray.algorithms.rrt_curriculum.algorithm:RRTCurriculumConfig",
        "copilot_ray.algorithms.rrt_curriculum.trial:RRTCurriculumTrial",
    ),
    # Planner-only baselines (the paper's Fig. 4b/4c): plain Tune trainables, no RLlib.
    "rrt_star": (
        "copilot_ray.algorithms.rrt_star.settings",
        "copilot_ray.algorithms.rrt_star.config:RRTStarConfig",
        "copilot_ray.algorithms.rrt_star.trial:RRTStarTrial",
    ),
    "sgt_pg": (
        "copilot_ray.algorithms.sgt_pg.settings",
        "copilot_ray.algorithms.sgt_pg.config:SGTPGConfig",
        "copilot_ray.algorithms.sgt_pg.trial:SGTPGTrial",
    ),
    "next": (
        "copilot_ray.algorithms.next.settings",
        "copilot_ray.algorithms.next.config:NEXTConfig",
        "copilot_ray.algorithms.next.trial:NEXTTrial",
    ),
    # HIRO-style two-level hierarchy (the paper's "hierarchical RL"): a Tune Trainable with its own env loop.
    "hrl": (
        "copilot_ray.algorithms.hrl.settings",
        "copilot_ray.algorithms.hrl.config:HRLConfig",
        "copilot_ray.algorithms.hrl.trial:HRLTrial",
    ),
}


class UnknownAlgorithmError(ValueError):
    """An algorithm name that is not registered."""


@dataclass(frozen=True)
class RunContext:
    """What a run adds to an algorithm's settings: the env, the seed, the CPUs of its process, the
    GPUs of its learner (0: the CPU, as on a machine without one) and its env-step budget."""

    env_id: str
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    num_env_runners: int = 0
    num_cpus_for_main_process: int = 1
    num_gpus: float = 0.0
    # The run's env-step budget (a sweep's stop.env_steps, train's --stop-env-steps), or None. An
    # algorithm whose iterations hold several repetitions (CO-PILOT's b) ends its last iteration at the
    # repetition that reaches it, so that long iterations do not run far past a shared budget.
    env_step_budget: int | None = None


@dataclass(frozen=True)
class AlgorithmEntry:
    """One registered algorithm, read off its module."""

    name: str
    settings: Mapping[str, Setting]
    metrics: tuple[str, ...]
    combination_problems: Callable[[Mapping[str, Any]], list[tuple[tuple[str, ...], Any, str]]]
    config_class: str  # "module:Class", imported by build_config only
    trial_class_path: str  # "module:Class", imported by trial_class only (a sweep's trainable)
    always_privileges: tuple[str, ...] = ()
    search_space: Mapping[str, Any] = field(default_factory=dict)  # raw domains (spec syntax)
    max_iteration_env_steps: Callable[[Mapping[str, Any]], int] | None = None
    max_env_steps_past_budget: Callable[[Mapping[str, Any]], int] | None = None
    # What its runs are labelled by in progress lines, MLflow tags and the report: label -> setting key
    # (K: tree_depth, b: repetitions, alpha_schedule); the settings module's LABELS.
    labels: Mapping[str, str] = field(default_factory=dict)
    gpu_learner: bool = False  # the settings module's GPU_LEARNER
    seed_stack: bool = False  # the settings module's SEED_STACK: seeds_per_trial > 1 is allowed
    presets: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)  # the settings module's PRESETS
    as_logged: Callable[[Mapping[str, Any]], dict[str, Any]] = dict  # the settings module's as_logged

    def privileges(self, values: Mapping[str, Any]) -> tuple[str, ...]:
        """The privileges a run uses at the effective setting `values` (copilot_ray.privileges)."""
        return privileges_of(self.settings, values, self.always_privileges)

    def defaults_as_logged(self, preset: str | None = None) -> dict[str, str]:
        """Every setting at its default (after `preset`) in the form its runs log them as MLflow params,
        without building a config (no RLlib): a report holds old runs' params against these."""
        values = self.as_logged(effective(self.settings, {"preset": preset} if preset else {}, self.presets))
        if "preset" in self.settings:
            values["preset"] = preset or "default"  # a run logs the preset it used by name
        return {key: logged_text(value) for key, value in values.items()}

    def build_config(self, values: Mapping[str, Any], run: RunContext) -> Any:
        """The algorithm's config for flat setting `values` and one run (imports the config class)."""
        return _load(self.config_class).from_settings(values, run)

    def trial_class(self) -> type:
        """The Tune trainable a sweep runs (imports Ray)."""
        return _load(self.trial_class_path)


# `<k>` in an algorithm's METRICS is a tree layer: 0..the deepest tree any setting allows.
MAX_LAYER = MAX_TREE_DEPTH


def metric_known(metric: str, patterns: Iterable[str]) -> bool:
    """Whether `metric` is one of an algorithm's METRICS (`<k>` matches a tree layer 0..MAX_LAYER)."""
    for pattern in patterns:
        if "<k>" in pattern:
            regex = re.escape(pattern).replace(re.escape("<k>"), r"(\d+)")
            m = re.fullmatch(regex, metric)
            if m and int(m.group(1)) <= MAX_LAYER:
                return True
        elif metric == pattern:
            return True
    return False


def _load(path: str) -> Any:
    module, name = path.split(":")
    return getattr(importlib.import_module(module), name)


def stackable_algorithms() -> list[str]:
    """The algorithms whose seeds can share one trial (SEED_STACK)."""
    return [name for name in algorithm_names() if get_algorithm(name).seed_stack]


def algorithm_names() -> list[str]:
    return sorted(ALGORITHMS)


def register_algorithm(name: str, settings_module: str, config_class: str, trial_class: str) -> None:
    """Make `algorithm: <name>` valid in specs; all three are imported on first use.

    In this process only: Ray's trial workers import the registry afresh, so an algorithm that sweeps
    run needs its line in ALGORITHMS itself."""
    ALGORITHMS[name] = (settings_module, config_class, trial_class)


def get_algorithm(name: str) -> AlgorithmEntry:
    """The algorithm `name`; raises UnknownAlgorithmError naming the known ones."""
    if name not in ALGORITHMS:
        close = difflib.get_close_matches(name, ALGORITHMS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UnknownAlgorithmError(f"unknown algorithm {name!r}{hint}; known: {algorithm_names()}")
    settings_module, config_class, trial_class = ALGORITHMS[name]
    module = importlib.import_module(settings_module)
    return AlgorithmEntry(
        name=name,
        settings=module.SETTINGS,
        metrics=tuple(module.METRICS),
        combination_problems=getattr(module, "combination_problems", lambda values: []),
        config_class=config_class,
        trial_class_path=trial_class,
        always_privileges=tuple(getattr(module, "PRIVILEGES", ())),
        search_space=dict(getattr(module, "SEARCH_SPACE", {})),
        max_iteration_env_steps=getattr(module, "max_iteration_env_steps", None),
        max_env_steps_past_budget=getattr(module, "max_env_steps_past_budget", None),
        labels=dict(getattr(module, "LABELS", {})),
        gpu_learner=bool(getattr(module, "GPU_LEARNER", False)),
        seed_stack=bool(getattr(module, "SEED_STACK", False)),
        presets=dict(getattr(module, "PRESETS", {})),
        as_logged=getattr(module, "as_logged", dict),
    )
