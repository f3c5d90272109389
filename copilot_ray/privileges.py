"""Privileges: what a method may use that its baselines may not, declared, counted and shown.

A comparison is fair only when every method gets the same information and the same control over the
environment, or when what differs is visible next to the result. Three privileges are named here:

* ``collision_checks``: ground-truth checks whether a segment (or motion) hits an obstacle. CO-PILOT's
  planner pays its collision penalty with them (the paper's Eq. 11), as RRT* and SGT-PG plan with them.
* ``reset_to_state``: the agent is put back at a state other than a task's start (every method may reset
  to a training task's start; a reset to a missed sub-goal is more).
* ``map_queries``: asking the map whether a state is free.

An algorithm declares them where they come from: a setting whose value grants some (`Setting.grants`,
e.g. ``after_failure: restart``), or its settings module's ``PRIVILEGES`` for what the method always
uses (RRT*'s collision checks). Every algorithm logs the three counts (``keys.PRIVILEGE_COUNTS``, 0 where
it has none); each trial's MLflow run is tagged with its privileges (``keys.PRIVILEGES_TAG``) and the
report lists them beside every result.

Standard library only: sweep specs and the analysis read this without Ray or torch.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

COLLISION_CHECKS = "collision_checks"
RESET_TO_STATE = "reset_to_state"
MAP_QUERIES = "map_queries"

DESCRIPTIONS = {
    COLLISION_CHECKS: "ground-truth collision checks of segments (the map)",
    RESET_TO_STATE: "resets of the agent to states other than a task's start",
    MAP_QUERIES: "questions to the map whether a state is free",
}
NONE = "none"


def privileges_of(
    settings: Mapping[str, Any], values: Mapping[str, Any], always: Iterable[str] = ()
) -> tuple[str, ...]:
    """The sorted privileges an algorithm with `settings` (Setting records) uses at `values` (the
    effective value of every setting), plus those it `always` uses."""
    granted = set(always)
    for key, setting in settings.items():
        grants = getattr(setting, "grants", None)
        if grants is not None and key in values:
            granted.update(grants(values[key]))
    unknown = granted - set(DESCRIPTIONS)
    if unknown:
        raise ValueError(f"unknown privilege(s) {sorted(unknown)}; known: {sorted(DESCRIPTIONS)}")
    return tuple(sorted(granted))


def tag_value(privileges: Iterable[str]) -> str:
    """The MLflow tag's value: the names joined by commas, or "none"."""
    names = sorted(privileges)
    return ",".join(names) if names else NONE


def from_tag(value: str | None) -> tuple[str, ...]:
    """The privileges of a run from its tag (() for "none", a missing tag or an old run)."""
    if not value or value == NONE:
        return ()
    return tuple(v for v in value.split(",") if v)
