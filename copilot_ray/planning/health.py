"""The run's learned state stays finite, and a drill can break it on purpose.

A NaN or an inf in the planner's or the cost model's weights poisons every plan after it and, left
alone, surfaces much later as an error about something else (a sub-goal outside the maze, a failed
assertion in an env). `check_finite` names the component and the iteration instead: the agent (GoalSAC) calls it on its curriculum's weights at
the start and the end of every iteration, and the error stops the trial there (a sweep retries it from
its last checkpoint, `fault_tolerance.max_failures` times, then marks it ERROR with this message and goes
on with the other trials).

`COPILOT_RAY_FAULT=<component>_nan@<iteration>[:seed=<s>]` (component: planner or cost_model) fills that
component's weights with NaN at the start of that iteration (of the runs with seed s only, when given):
the fault drill (`benchmarks/fault_drills.py --drills nan`). Set it in the environment of the process that
starts Ray, so that trial workers inherit it.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterable, Mapping

import torch

FAULT_ENV = "COPILOT_RAY_FAULT"
COMPONENTS = ("planner", "cost_model")
_FAULT = re.compile(r"^(" + "|".join(COMPONENTS) + r")_nan@(\d+)(?::seed=(-?\d+))?$")


class NonFiniteStateError(FloatingPointError):
    """Learned weights became NaN or infinite."""


def parse_fault(text: str | None) -> tuple[str, int, int | None] | None:
    """`"planner_nan@3"` -> ("planner", 3, None), `"planner_nan@3:seed=1"` -> ("planner", 3, 1); None for
    no fault; ValueError naming the variable otherwise."""
    if not text:
        return None
    match = _FAULT.match(text.strip())
    if match is None:
        raise ValueError(
            f"{FAULT_ENV}={text!r} is invalid: use <component>_nan@<iteration>[:seed=<s>] with component one "
            f"of {', '.join(COMPONENTS)} (e.g. planner_nan@3 or planner_nan@3:seed=1)"
        )
    seed = match.group(3)
    return match.group(1), int(match.group(2)), None if seed is None else int(seed)


def injected_fault(iteration: int, seed: int | None = None) -> str | None:
    """The component whose weights the drill breaks at the start of `iteration` (1-based) of a run with
    `seed`, if any."""
    fault = parse_fault(os.environ.get(FAULT_ENV))
    if fault is None or fault[1] != iteration or fault[2] not in (None, seed):
        return None
    return fault[0]


def fill_nan(parameters: Iterable[torch.Tensor]) -> None:
    with torch.no_grad():
        for p in parameters:
            p.fill_(math.nan)


def check_finite(components: Mapping[str, Iterable[torch.Tensor]], iteration: int, when: str) -> None:
    """Raises NonFiniteStateError naming every component with a non-finite weight."""
    bad = [
        name
        for name, parameters in components.items()
        if any(not bool(torch.isfinite(p).all()) for p in parameters)
    ]
    if bad:
        raise NonFiniteStateError(
            f"iteration {iteration}: non-finite (NaN or inf) weights in the {' and the '.join(bad)} {when}; "
            "the run stops here (its last checkpoint is from before)"
        )
