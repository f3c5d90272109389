"""Settings of ``algorithm: sorb_map``: SoRB (copilot_ray.algorithms.sorb) with ``sorb.edge_check: map``
by default, so that its search graph drops every edge whose straight segment crosses a wall.

The privilege-matched twin of SoRB: CO-PILOT's planner pays its collision penalty with ground-truth
collision checks; this SoRB gets the same kind of map access, every check counted
(``copilot/privileges/collision_checks``). Its agent, search space and metrics are SoRB's.
"""

from __future__ import annotations

from dataclasses import replace

from copilot_ray.algorithms.sorb.settings import (
    GPU_LEARNER,
    METRICS,
    SEARCH_SPACE,
    SEED_STACK,
    combination_problems,
    max_iteration_env_steps,
)
from copilot_ray.algorithms.sorb.settings import SETTINGS as SORB_SETTINGS

SETTINGS = {
    **SORB_SETTINGS,
    "sorb.edge_check": replace(SORB_SETTINGS["sorb.edge_check"], default="map"),
}

__all__ = [
    "GPU_LEARNER",
    "SEED_STACK",
    "METRICS",
    "SEARCH_SPACE",
    "SETTINGS",
    "combination_problems",
    "max_iteration_env_steps",
]
