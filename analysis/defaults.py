"""Each configuration's settings, as its runs logged them, held against the defaults of the code drawing
the report: is this row the method's default as the code stands now?

A comparison runs at one commit and is read at a later one, whose defaults may have moved (CO-PILOT's
planner mean did). Per configuration the report lists the settings whose logged value differs from this
checkout's default for its algorithm and preset (set by the spec, its search, stage 1's winner or a
variant, or a default changed since), and the settings its runs did not log (added since their commit,
so they ran that setting's earlier behaviour, which no param records). The defaults come from the
settings modules (`AlgorithmEntry.defaults_as_logged`), in the form the runs log them, without building
a config: no Ray.
"""

from __future__ import annotations

import math

from copilot_ray.keys import ALGORITHM_TAG, GIT_COMMIT_TAG
from copilot_ray.registry import UnknownAlgorithmError, get_algorithm

from .aggregate import ConfigSummary
from .tables import Table

TEXT = (
    "Each configuration's settings as its runs logged them (its first seed: a configuration's seeds share "
    "them), against the defaults of the code drawing this report (its commit is under Provenance) for the "
    "same algorithm and preset. 'Differs' lists the runs' value with this checkout's default in brackets: "
    "a value the spec, its search, stage 1's winner or a variant set, or a default that changed since the "
    "runs' commit. 'Not logged' lists settings this checkout has that the runs' params lack: added since "
    "their commit (the runs had the behaviour from before that setting), or not logged by it. A row with "
    "neither ran exactly this checkout's defaults."
)
DEFAULTS_HEADER = [
    "configuration",
    "runs' commit",
    "differs: runs' value (this checkout's default)",
    "not logged",
]
SAME = "none"


def short(text: str) -> str:
    """A logged number at 4 significant digits (a tuned learning rate's 17), anything else as it is."""
    try:
        value = float(text)
    except ValueError:
        return text
    if not math.isfinite(value) or text.lstrip("-").isdigit():
        return text
    return f"{value:.4g}"


def differences(config: ConfigSummary) -> tuple[list[tuple[str, str, str]], list[tuple[str, str]]] | str:
    """(settings whose logged value differs: (key, logged, default); settings not logged: (key, default))
    of `config`'s first trial, or why it cannot be held against this checkout's defaults."""
    trial = config.all_trials[0]
    name = trial.tags.get(ALGORITHM_TAG, "")
    try:
        entry = get_algorithm(name)
    except UnknownAlgorithmError:
        return f"algorithm {name!r} is not one of this checkout's" if name else "no algorithm tag"
    preset = trial.params.get("preset")  # logged by name ("default" too) by an algorithm with presets
    if preset is not None and preset not in entry.presets:
        return f"preset {preset!r} is not one of this checkout's {name} presets"
    defaults = entry.defaults_as_logged(preset)
    if not set(defaults) & set(trial.params):
        return "its runs logged no settings"
    differ = [
        (key, trial.params[key], value)
        for key, value in sorted(defaults.items())
        if key in trial.params and trial.params[key] != value
    ]
    missing = [(key, value) for key, value in sorted(defaults.items()) if key not in trial.params]
    return differ, missing


def defaults_table(configs: list[ConfigSummary]) -> Table | None:
    """One row per configuration (None: no configuration has a run)."""
    rows = []
    for c in configs:
        if not c.all_trials:
            continue
        commit = c.all_trials[0].tags.get(GIT_COMMIT_TAG, "")[:7] or "-"
        found = differences(c)
        if isinstance(found, str):
            rows.append([c.label, commit, f"not compared: {found}", ""])
            continue
        differ, missing = found
        rows.append(
            [
                c.label,
                commit,
                "; ".join(f"{k} = {short(v)} ({short(d)})" for k, v, d in differ) or SAME,
                "; ".join(f"{k} (now {short(d)})" for k, d in missing) or SAME,
            ]
        )
    return Table(DEFAULTS_HEADER, rows) if rows else None
