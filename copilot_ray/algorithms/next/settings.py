"""Every setting of the NEXT baseline (``algorithm: next``), declared once (see copilot_ray.settings).

Tune iteration 0 imitates ``num_demos`` demonstrations on training tasks (RRT* for ``demo_time_s`` each,
or this search with uniform sampling) for ``demo_train_steps``; each of the next ``self_improve_rounds``
iterations searches ``tasks_per_round`` random training tasks with the model, imitates what it solved and
trains ``round_train_steps``. Every iteration then searches the first ``eval_num_tasks`` test tasks and
scores the paths (copilot_ray.planning.path_metrics), against RRT* when ``rrt_reference_time_s`` > 0; the
run is done after the last round. The search and the model are described in
copilot_ray.planning.next_planner.
"""

from __future__ import annotations

from copilot_ray import keys
from copilot_ray.privileges import COLLISION_CHECKS
from copilot_ray.settings import bool_setting, choice_setting, float_setting, int_setting, sizes_setting

DEMONSTRATORS = ("rrt_star", "search")

SETTINGS = {
    s.key: s
    for s in (
        # ------------------------------------------------------------------ the search (one query)
        float_setting(
            "step_length",
            "next",
            0.05,
            "steering step of every extension, in the env's distance (also the visit kernel's width)",
            0.0,
            lo_open=True,
            why="about half a four-rooms cell (1/11) and twice the success radius; the paper's code "
            "uses RRT_EPS = 0.05 on [-1, 1]^2 (half of it on the unit square)",
        ),
        int_setting("max_iterations", "next", 3000, "iterations per query at most (then unsolved)", 1),
        int_setting("max_checks", "next", 20000, "collision checks per query at most (then unsolved)", 1),
        int_setting(
            "improve_iterations",
            "next",
            0,
            "iterations a test query goes on after its first solution (rewiring shortens the path)",
            0,
        ),
        float_setting(
            "exploration",
            "next",
            1.0,
            "UCB weight c of the visit bonus against the value (in units of the space's diameter)",
            0.0,
            why="the paper's code's c = 1; 0.3 .. 2 gave alike checks on four-rooms, 0.1 and less got stuck",
        ),
        float_setting(
            "uniform_share",
            "next",
            0.1,
            "share of iterations that extend towards a uniform sample (RRT), keeping the search complete",
            0.0,
            1.0,
        ),
        float_setting(
            "goal_bias", "next", 0.05, "share of iterations that extend towards the goal", 0.0, 1.0
        ),
        int_setting("candidates", "next", 10, "policy samples scored per guided expansion (paper's k)", 1),
        float_setting(
            "policy_std",
            "next",
            0.3,
            "the policy Gaussian's std, in steps per distance-weighted dim (the paper's code: 0.3 RRT_EPS)",
            0.0,
            lo_open=True,
        ),
        float_setting(
            "rewire_factor",
            "next",
            3.0,
            "choose-parent and rewire radius, in steps (the paper's code: 3)",
            0.0,
        ),
        # ------------------------------------------------------------------ the model
        sizes_setting("hidden", "next", [128, 128], "hidden sizes of the policy and of the value MLP"),
        float_setting("lr", "next", 1e-3, "Adam learning rate", 0.0, lo_open=True),
        int_setting("batch_size", "next", 256, "imitation pairs per gradient step", 1),
        bool_setting(
            "hindsight",
            "next",
            True,
            "also imitate every sub-path of a solved path, its end as the goal",
        ),
        # ------------------------------------------------------------------ training
        choice_setting(
            "demonstrator",
            "next",
            "rrt_star",
            "rrt_star: OMPL's RRT* for demo_time_s per task (time-limited, not bit-reproducible); search: "
            "this search with uniform sampling (the paper code's RRTS_plan), reproducible",
            DEMONSTRATORS,
        ),
        int_setting("num_demos", "next", 50, "demonstrations, on the first training tasks", 0),
        float_setting(
            "demo_time_s",
            "next",
            1.0,
            "RRT*'s time per demonstration (demonstrator: rrt_star)",
            0.0,
            lo_open=True,
        ),
        int_setting("demo_train_steps", "next", 2000, "gradient steps on the demonstrations", 0),
        int_setting("self_improve_rounds", "next", 5, "self-improvement rounds (one Tune iteration each)", 0),
        int_setting("tasks_per_round", "next", 30, "training tasks searched per self-improvement round", 1),
        int_setting("round_train_steps", "next", 500, "gradient steps per self-improvement round", 0),
        int_setting(
            "train_improve_iterations",
            "next",
            300,
            "iterations a training search (self-improvement; demonstrator: search) goes on after its first "
            "solution, shortening the path it imitates",
            0,
        ),
        # ------------------------------------------------------------------ evaluation
        int_setting("eval_num_tasks", "next", 100, "test tasks searched and scored per iteration", 1),
        float_setting(
            "rrt_reference_time_s",
            "next",
            3.0,
            "RRT*'s time per task for the *_vs_rrt metrics (computed once per env, cached); 0: none",
            0.0,
        ),
    )
}

# What a NEXT run logs that a sweep may optimise or stop on.
# A planner that searches the map: every segment or motion it considers is a ground-truth check.
PRIVILEGES = (COLLISION_CHECKS,)
METRICS: tuple[str, ...] = (*keys.PATH_METRICS, keys.ENV_STEPS)
