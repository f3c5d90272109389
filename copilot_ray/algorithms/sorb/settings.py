"""Every setting of the SoRB baseline (``algorithm: sorb``), declared once.

SoRB trains the same goal-conditioned SAC as the HER baseline (its settings, relabelling included) and
adds search at test time: a graph over ``sorb.graph_size`` replayed states whose edges are the critic's
distance estimates up to ``sorb.max_edge_steps``; the agent follows the shortest path's waypoints
(``sorb.waypoint_steps`` steps each, ``tau_max`` in all, the same budget as every other method). It
"starts later": no search before ``sorb.pretrain_env_steps`` env steps (evaluations before that are its
agent alone, so its curve shares every method's cadence).
"""

from __future__ import annotations

from dataclasses import replace

from copilot_ray import keys
from copilot_ray.algorithms.sac.her_settings import SEARCH_SPACE as HER_SEARCH_SPACE
from copilot_ray.algorithms.sac.settings import (  # GPU_LEARNER: HER's agent, on the same learner
    AGENT,
    GPU_LEARNER,
    HINDSIGHT,
    SEED_STACK,
    combination_problems,
    max_iteration_env_steps,
)
from copilot_ray.privileges import COLLISION_CHECKS
from copilot_ray.settings import choice_setting, int_setting

EDGE_CHECKS = ("none", "map")

SEARCH = [
    int_setting(
        "sorb.pretrain_env_steps",
        "sorb",
        20_000,
        "env steps of goal-conditioned SAC before the first search (evaluated as the agent alone until then)",
        0,
    ),
    int_setting(
        "sorb.graph_size",
        "sorb",
        1000,
        "replayed states in the search graph (its nodes; SoRB's 1000): on four-rooms a HER agent after "
        "113k env steps succeeded on 0.29 of the test tasks with 1000, 0.19 with 500 (0.16 alone)",
        2,
    ),
    int_setting(
        "sorb.max_edge_steps",
        "sorb",
        50,
        "longest edge kept, in the critic's estimated agent steps (SoRB's cutoff)",
        1,
    ),
    choice_setting(
        "sorb.edge_check",
        "sorb",
        "none",
        "which edges the graph keeps: those the critic puts within max_edge_steps (SoRB), or of those the ones "
        "whose straight segment the map finds free of walls (SoRB with CO-PILOT's map access)",
        EDGE_CHECKS,
        # Every kept edge asks the map (counted as copilot/privileges/collision_checks).
        grants=lambda v: (COLLISION_CHECKS,) if v == "map" else (),
    ),
    int_setting(
        "sorb.waypoint_steps",
        "sorb",
        100,
        "steps the agent may take towards one waypoint before heading for the next",
        1,
    ),
]
# SoRB's agent may also train without relabelling (her.n_sampled_goal 0).
_HINDSIGHT = [
    replace(
        s, check=lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0, rule="an integer >= 0"
    )
    if s.key == "her.n_sampled_goal"
    else s
    for s in HINDSIGHT
]
SETTINGS = {s.key: s for s in (*AGENT, *_HINDSIGHT, *SEARCH)}
METRICS: tuple[str, ...] = (
    *keys.validation_metrics(
        keys.EVAL_SUCCESS, keys.SUCCESS_PLANNED, keys.SUCCESS_DIRECT, keys.EVAL_SUCCESS_AUC, keys.EVAL_RETURN
    ),
    keys.EVAL_SUCCESS,
    keys.SUCCESS_PLANNED,
    keys.SUCCESS_DIRECT,
    keys.EVAL_SUCCESS_AUC,
    keys.ENV_STEPS,
    keys.SORB_GRAPH_EDGES,
    keys.SORB_WAYPOINTS,
    # the plan its graph search gives, scored as a motion planner's, once the search has started
    *keys.PATH_METRICS,
)

# HER's space (SoRB trains HER's agent) plus the search's structure: the graph's size and edge cutoff.
SEARCH_SPACE: dict[str, dict] = {
    **HER_SEARCH_SPACE,
    "sorb.graph_size": {"categorical": [500, 1000, 2000]},
    "sorb.max_edge_steps": {"categorical": [25, 50, 100]},
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
