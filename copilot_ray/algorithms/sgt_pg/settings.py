"""Every setting of the SGT-PG baseline (``algorithm: sgt_pg``), declared once (see copilot_ray.settings).

pi_p's settings are CO-PILOT's ``planner.*`` settings with the reference code's exploration (a constant
absolute std 0.05: ``planner.std_final`` defaults to null here) and unbounded mean (``planner.mean`` free).
Every Tune iteration runs ``phases_per_iteration`` planner phases (Algorithm 1 on ``task_batch_size``
training tasks, one PPO update per layer) and then scores the mean tree's finest path on the first
``eval_num_tasks`` test tasks (copilot_ray.planning.path_metrics), against RRT* when
``rrt_reference_time_s`` > 0.
"""

from __future__ import annotations

import dataclasses

from copilot_ray import keys
from copilot_ray.algorithms.copilot.settings import SETTINGS as COPILOT_SETTINGS
from copilot_ray.privileges import COLLISION_CHECKS
from copilot_ray.settings import MAX_TREE_DEPTH, float_setting, int_setting

# SGT-PG as its reference code: where CO-PILOT's planner default is a measured addition, the reference's.
_REFERENCE = {
    "planner.std_final": (
        None,
        "SGT-PG's reference code keeps its std constant; CO-PILOT's annealing is a measured addition",
    ),
    "planner.mean": (
        "free",
        "SGT-PG's reference code's unbounded mean; CO-PILOT's leaky mean is a measured addition",
    ),
}
_PLANNER = [
    dataclasses.replace(s, default=_REFERENCE[s.key][0], why=_REFERENCE[s.key][1])
    if s.key in _REFERENCE
    else s
    for s in COPILOT_SETTINGS.values()
    if s.target == "planner"
]

SETTINGS = {
    s.key: s
    for s in (
        int_setting(
            "tree_depth", "sgt_pg", 5, "sub-goal tree depth K (2^K finest segments)", 1, MAX_TREE_DEPTH
        ),
        int_setting("task_batch_size", "sgt_pg", 30, "training tasks per planner phase (paper 4.1)", 1),
        int_setting(
            "phases_per_iteration", "sgt_pg", 10, "planner phases per Tune iteration (then a score)", 1
        ),
        float_setting(
            "collision_penalty", "sgt_pg", 10.0, "cost added per colliding segment (paper Eq. 11)", 0.0
        ),
        int_setting("eval_num_tasks", "sgt_pg", 100, "test tasks scored per iteration", 1),
        float_setting(
            "rrt_reference_time_s",
            "sgt_pg",
            3.0,
            "RRT*'s time per task for the *_vs_rrt metrics (computed once per env, cached); 0: none",
            0.0,
        ),
        *_PLANNER,
    )
}

# What an SGT-PG run logs that a sweep may optimise or stop on.
# A planner that searches the map: every segment or motion it considers is a ground-truth check.
PRIVILEGES = (COLLISION_CHECKS,)
LABELS = {"K": "tree_depth"}  # its runs are labelled by their tree depth, as CO-PILOT's
METRICS: tuple[str, ...] = (*keys.PATH_METRICS, keys.PLANNER_UPDATES, keys.ENV_STEPS)
