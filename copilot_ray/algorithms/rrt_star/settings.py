"""Every setting of the RRT* baseline (``algorithm: rrt_star``), declared once (see copilot_ray.settings).

A trial plans the first ``eval_num_tasks`` test tasks of its env, ``tasks_per_iteration`` per Tune
iteration, each with ``time_limit_s`` seconds (RRT* keeps shortening its path until then), and ends when
all are planned. What it logs is the reference the other planners are normalised by; the finished run is
also stored in the shared RRT* reference cache (copilot_ray.planning.path_metrics).
"""

from __future__ import annotations

from copilot_ray import keys
from copilot_ray.privileges import COLLISION_CHECKS
from copilot_ray.settings import float_setting, int_setting

SETTINGS = {
    s.key: s
    for s in (
        float_setting(
            "time_limit_s", "rrt_star", 3.0, "planning time per task (OMPL's solve time)", 0.0, lo_open=True
        ),
        int_setting(
            "eval_num_tasks", "rrt_star", 100, "test tasks planned (the paper's test set has 100)", 1
        ),
        int_setting(
            "tasks_per_iteration", "rrt_star", 10, "tasks planned per Tune iteration (a checkpoint each)", 1
        ),
        float_setting(
            "range",
            "rrt_star",
            None,
            "OMPL's maximum edge length; null: OMPL's default (a fraction of the space's extent)",
            0.0,
            lo_open=True,
            optional=True,
        ),
    )
}

# What an RRT* run logs that a sweep may optimise or stop on.
# A planner that searches the map: every segment or motion it considers is a ground-truth check.
PRIVILEGES = (COLLISION_CHECKS,)
METRICS: tuple[str, ...] = (*keys.PATH_METRICS, keys.ENV_STEPS)
