"""Algorithm names -> where they are declared. A new algorithm is one module plus one line in
ALGORITHMS (or one `register_algorithm` call).

A line names two things, "settings_module" and "config_module:ConfigClass" (one module may be both).
The settings module must import without Ray (sweep specs are validated against it before anything
starts) and provide:

    SETTINGS: dict[str, Setting]          every key a spec's config/search/variants, the train CLI and
                                          benchmarks' --set accept (copilot_ray.settings.Setting)
    METRICS: tuple[str, ...]              what it logs that a sweep may optimise (`<k>`: a tree layer)
    combination_problems(values)          optional: [(keys, value, why)] for values that clash together

The config class (an RLlib AlgorithmConfig, imported only when a run is built) provides
`from_settings(values, run)`: flat setting values + a RunContext -> a config ready to build.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from copilot_ray.settings import Setting

ALGORITHMS: dict[str, tuple[str, str]] = {
    "copilot": (
        "copilot_ray.algorithms.copilot.settings",
        "copilot_ray.algorithms.copilot.algorithm:CoPilotConfig",
    ),
}


class UnknownAlgorithmError(ValueError):
    """An algorithm name that is not registered."""


@dataclass(frozen=True)
class RunContext:
    """What a run adds to an algorithm's settings: the env, the seed and the CPUs of its process."""

    env_id: str
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    num_env_runners: int = 0
    num_cpus_for_main_process: int = 1


@dataclass(frozen=True)
class AlgorithmEntry:
    """One registered algorithm, read off its module."""

    name: str
    settings: Mapping[str, Setting]
    metrics: tuple[str, ...]
    combination_problems: Callable[[Mapping[str, Any]], list[tuple[tuple[str, ...], Any, str]]]
    config_class: str  # "module:Class", imported by build_config only

    def build_config(self, values: Mapping[str, Any], run: RunContext) -> Any:
        """The algorithm's config for flat setting `values` and one run (imports the config class)."""
        module, name = self.config_class.split(":")
        return getattr(importlib.import_module(module), name).from_settings(values, run)


def algorithm_names() -> list[str]:
    return sorted(ALGORITHMS)


def register_algorithm(name: str, settings_module: str, config_class: str) -> None:
    """Make `algorithm: <name>` valid in specs; both are imported on first use."""
    ALGORITHMS[name] = (settings_module, config_class)


def get_algorithm(name: str) -> AlgorithmEntry:
    """The algorithm `name`; raises UnknownAlgorithmError naming the known ones."""
    if name not in ALGORITHMS:
        close = difflib.get_close_matches(name, ALGORITHMS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UnknownAlgorithmError(f"unknown algorithm {name!r}{hint}; known: {algorithm_names()}")
    settings_module, config_class = ALGORITHMS[name]
    module = importlib.import_module(settings_module)
    return AlgorithmEntry(
        name=name,
        settings=module.SETTINGS,
        metrics=tuple(module.METRICS),
        combination_problems=getattr(module, "combination_problems", lambda values: []),
        config_class=config_class,
    )
