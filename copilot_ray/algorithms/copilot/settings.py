"""Every CO-PILOT setting, declared once: its type, default, allowed values and a one-line doc.

Everything else is generated from `SETTINGS`: CoPilotConfig's defaults and its validation, the keys and
ranges a sweep spec accepts (`config`, `search`, `variants`), `python -m copilot_ray.train`'s
command line, `benchmarks/maze_learning.py --set`, and docs/settings.md's two settings tables
(`python -m copilot_ray.algorithms.copilot.settings` prints them; a test fails when the page's copy
is stale).

A setting's `key` is its name everywhere. Dotted keys live in a nested dict of the config
(`planner.std` is `config.planner["std"]`) or are one field of the alpha schedule
(`alpha_schedule.start`, sweep specs only). `target` says where `CoPilotConfig.from_settings` puts the value:
`copilot` -> `.copilot(key=...)`, `planner` / `cost_model` -> `.copilot(planner={field: ...})`,
`alpha_schedule` -> one field of the schedule, `training` -> `.training(key=...)` (SAC's own).

Where the paper is ambiguous, or its literal reading starved the agent on the long-horizon maze, the
setting has a `why` (the measured reason for its default) and `PRESETS["paper_literal"]` holds the
paper's (or, where it is silent, the public reference code's) reading.

No Ray import here: a sweep spec is validated against this table before anything starts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from copilot_ray import keys
from copilot_ray.algorithms.sac import settings as agent_settings
from copilot_ray.planning.alpha_schedule import CLOCKS as ALPHA_CLOCKS
from copilot_ray.planning.alpha_schedule import KINDS as ALPHA_KINDS
from copilot_ray.planning.alpha_schedule import PRESETS as ALPHA_PRESETS
from copilot_ray.planning.alpha_schedule import AlphaSchedule
from copilot_ray.planning.planner_modes import ANGLE_MODES, MEAN_MODES, NOISE_MODES
from copilot_ray.planning.segment_cost import COLLISION_COSTS
from copilot_ray.privileges import COLLISION_CHECKS
from copilot_ray.settings import (
    MAX_TREE_DEPTH,
    Setting,
    bool_setting,
    choice_setting,
    float_setting,
    int_setting,
    markdown_value,
    numbers_setting,
    replace_between,
    sizes_setting,
)

# Where CoPilotConfig.from_settings puts a setting: .copilot(key=...), .agent(key=...) (the goal-conditioned
# SAC agent's, sac/settings.py), .copilot(planner={field: ...}), .copilot(cost_model={field: ...}), one
# field of the alpha schedule, .training(key=...).
TARGETS = ("copilot", "agent", "planner", "cost_model", "alpha_schedule", "training")

_int, _float, _bool, _choice, _sizes = int_setting, float_setting, bool_setting, choice_setting, sizes_setting
# The goal-conditioned SAC agent's settings (CO-PILOT's agent is that agent): CO-PILOT takes them from
# there, with its own defaults where they differ (a sub-task, not a task, per episode).
_A = agent_settings.SETTINGS
_A_TREE = {s.key: s for s in agent_settings.TREE_TRAVERSAL}


def _schedule_ok(v: Any) -> bool:
    if not isinstance(v, str | dict):
        return False
    AlphaSchedule.from_dict(v)  # raises ValueError naming the bad field
    return True


def _alpha_field(key: str, kind_setting: Any, *args: Any, **kw: Any) -> Setting:
    """One field of the alpha schedule (sweep specs only): its default comes from the schedule."""
    return kind_setting(f"alpha_schedule.{key}", "alpha_schedule", None, *args, on_cli=False, **kw)


# Choices of the readings (the paper's first).
STEP_LIMITS = agent_settings.STEP_LIMITS
AFTER_FAILURE = agent_settings.AFTER_FAILURE
SUBTASK_REWARDS = agent_settings.SUBTASK_REWARDS
AGENT_COLLISIONS = agent_settings.AGENT_COLLISIONS
AGENT_INPUTS = agent_settings.AGENT_INPUTS
FAILED_SUBTASK_COSTS = ("end_state", "lower_bound")
TRAVERSAL_TREES = ("sampled", "mean")
EVAL_ACTIONS = keys.EVAL_ACTIONS

# ------------------------------------------------------------------------------------- the table
# Grouped by concern; the order is the order of the settings page's table and of `train --help`.
_TREE = [
    _int(
        "tree_depth",
        "copilot",
        5,
        "K: a tree has 2^K + 1 sub-goals (the agent without a planner is algorithm sac)",
        1,
        MAX_TREE_DEPTH,
        note=" (K > 10 is too deep for memory: 2^(K+1) - 1 sub-tasks per task)",
        # The planner's collision penalty (Eq. 11) asks the map about every segment it costs.
        grants=lambda k: (COLLISION_CHECKS,) if isinstance(k, int) and k > 0 else (),
    ),
    _int(
        "repetitions", "copilot", 5, "b: traversals of every task mini-batch per iteration (paper 4.1: 5)", 1
    ),
    replace(
        _A["task_batch_size"],
        default=2,
        doc="tasks the agent traverses per iteration (paper 4.1: a mini-batch of 30)",
        why="not a reading: iteration size. With 30 tasks x b = 5 one iteration at K = 5 is up to 236k env "
        "steps (30 x 5 x 63 x 25), so a 300k-step run gets one or two evaluations; with 2 it is at most 16k "
        "(about 10k in practice). The planner keeps its batch of 30 (planner_task_batch_size)",
    ),
    _int(
        "planner_task_batch_size",
        "copilot",
        30,
        "tasks in the planner's PPO batch per phase: the iteration's tasks plus other training tasks",
        1,
        why="the planner's PPO batch (not a paper reading). On the agent's 2 tasks alone, collision-free test "
        "plans fell from 0.85 to 0.36-0.45 within 10 phases; on 30 (the paper's mini-batch) they stayed at "
        "0.80-0.91",
    ),
    Setting(
        "alpha_schedule",
        "schedule",
        "alpha_schedule",
        "paper_per_task",
        "the planner's cost mix alpha x Euclidean + (1 - alpha) x time cost: a preset name or a schedule mapping",
        _schedule_ok,
        f"a preset name {list(ALPHA_PRESETS)} or a schedule mapping with kind in {list(ALPHA_KINDS)}"
        " (to search over kinds use alpha_schedule.kind)",
    ),
]
_ALPHA_FIELDS = [
    _alpha_field(
        "kind", _choice, "schedule kind: the schedule is built from its dotted fields alone", ALPHA_KINDS
    ),
    _alpha_field(
        "clock", _choice, "what the schedule counts: iterations, or each task's repetitions", ALPHA_CLOCKS
    ),
    _alpha_field("alpha", _float, "constant alpha", 0.0, 1.0),
    _alpha_field("start", _float, "alpha at the start (linear, exponential)", 0.0, 1.0),
    _alpha_field("end", _float, "alpha at the end (linear, exponential)", 0.0, 1.0),
    _alpha_field("duration", _float, "clock ticks from start to end (linear)", 0.0, lo_open=True),
    _alpha_field("decay", _float, "factor per tick (exponential)", 0.0, 1.0, lo_open=True, hi_open=True),
    _alpha_field(
        "boundaries",
        numbers_setting,
        "clock values where a step schedule moves on",
        what="numbers (increasing clock values)",
    ),
    _alpha_field("values", numbers_setting, "alpha of each step", 0.0, 1.0, "alpha values in [0, 1]"),
]
_TRAVERSAL = [
    replace(
        _A["tau_max"],
        default=25,
        doc="step limit of one sub-task (paper 4.1: 25)",
        why="the paper's; `step_limit: scaled` made failing upper layers cost ~3x the env steps",
    ),
    replace(_A_TREE["step_limit"], why="the paper's"),
    replace(
        _A_TREE["after_failure"],
        why="the paper's, and chosen on VALIDATION tasks among the readings without resets or map queries (restart resets the "
        "agent to a missed sub-goal after a map query, which no baseline may): mean validation success AUC over "
        "four-rooms and u-maze, 2 seeds each, 60k env steps: continue 0.095, abort_layer 0.030; final "
        "validation success 0.16 vs 0.08. Weak: continue's lead is one u-maze seed (AUC 0.34, final 0.59; "
        "its other three runs <= 0.03), the median AUC favours abort_layer (0.026 vs 0.020) "
        "(`bash scripts/run_at_commit.sh --commit 4166145 sweeps/choose_defaults.yaml`). Biased against "
        "abort_layer: at that commit a call that ran out of plan after a dropped layer stepped placeholder "
        "episodes, counted against its budget (fixed on 2026-11-28; not rerun)",
    ),
    replace(
        _A_TREE["subtask_reward"],
        why="a layer-5 reward of 1/32 is worth less than the entropy bonus SAC keeps by not reaching the "
        "sub-goal: test success 0.00 at 10k and 21k env steps with `halving`, 0.16 at 18k and 0.44 at 27k "
        "with `uniform`",
    ),
    replace(_A["reward_scale"], why="the paper's"),
    replace(_A["agent_collision"], why="the paper's; `penalty` and `terminate` are there to try"),
    _A["agent_collision_penalty"],
    replace(
        _A["agent_input"],
        why="the delta is a function of s and g; without it the finest sub-tasks stayed at 51-58 % success "
        "and test success at 0.00-0.01 over 31k env steps; with it 0.44 at 27k",
    ),
    _choice(
        "traversal_tree",
        "copilot",
        "mean",
        "the tree the agent traverses: a sample of pi_p, or pi_p's mean",
        TRAVERSAL_TREES,
        why="with pi_p's std 0.05 the sampled layer-5 segments averaged 0.073-0.10 long while a sub-task covers "
        "at most 0.0875; the planner's PPO still learns from its own samples",
    ),
    _choice(
        "failed_subtask_cost",
        "copilot",
        "lower_bound",
        "D_tau's tuple for a failed sub-task: (start, where it stopped, steps) or (start, sub-goal, a lower bound of the steps)",
        FAILED_SUBTASK_COSTS,
        why="tau_hat only ever saw tuples <= 0.06 long and priced a 0.012 segment at 4-7x its length but a 0.1 "
        "one at 1x, so the finest segments drifted longer (share beyond reach 0.06 -> 0.16). Weak evidence: "
        "the drift showed under both readings in the probes",
    ),
    _A["subtasks_per_sample"],
]
_PLANNER = [
    _int(
        "planner_warm_start",
        "copilot",
        1000,
        "planner phases (Euclidean cost, no env steps) before the agent's first traversal",
        0,
        why="~4 min of one core on maze-point (0.20-0.24 s per phase on one torch thread, as train runs it, "
        "with or without the other core busy: `PYTHONPATH=. .venv/bin/python benchmarks/warm_start.py "
        "[--busy-core]`, docs/measured.md), no env steps, so that the agent's first sub-goals are not the "
        "untrained planner's. On VALIDATION tasks (planner only, seeds 0-3, `bash benchmarks/planner_validation_probe.sh`, "
        "docs/planner_probe): collision-free plans before the agent's first step 0.75-0.92 on four-rooms and "
        "0.97-1.00 on u-maze; four-rooms seed 3 collapsed between phases 800 and 900 (0.00, see Known limits)",
    ),
    _bool(
        "planner_frozen",
        "copilot",
        False,
        "no planner update after the warm start: the agent traverses the warm-started planner's trees "
        "(the co-training ablation; the planner then plans only the tasks the agent traverses)",
    ),
    _choice(
        "collision_cost",
        "copilot",
        "indicator",
        "Eq. 11's collision term: a penalty per colliding segment (paper) or per unit of length in collision (reference code)",
        COLLISION_COSTS,
    ),
    _float(
        "collision_penalty",
        "copilot",
        None,
        "the collision term's weight; null: 10 for indicator (paper), 100 for length",
        0.0,
        optional=True,
    ),
    _sizes(
        "planner.hidden",
        "planner",
        [20, 20, 20],
        "pi_p's hidden layers, one tanh MLP per tree layer (reference code)",
    ),
    _float(
        "planner.std",
        "planner",
        0.05,
        "pi_p's exploration std (absolute; with noise relative: a fraction of the parent segment)",
        0.0,
        lo_open=True,
    ),
    _choice(
        "planner.noise",
        "planner",
        "absolute",
        "pi_p's std: absolute (reference code) or relative to the parent segment",
        NOISE_MODES,
    ),
    _float(
        "planner.std_final",
        "planner",
        0.015,
        "the std is annealed linearly to this over std_anneal_phases planner phases; null: constant std",
        0.0,
        lo_open=True,
        optional=True,
        why="on VALIDATION tasks (planner only, 1000 phases, seeds 0-3, docs/planner_probe): an agent driving "
        "straight at each sub-goal completed 0.66-0.71 (four-rooms) and 0.88-0.98 (u-maze) of the annealed "
        "plans, 0.27-0.48 and 0.22-0.37 of the constant-std ones (finest paths 2.9-3.9x / 1.2-1.6x the "
        "shortest against 3.2-5.3x): the noise keeps PPO's mean paths away from walls by wiggling them. The "
        "cost: a smaller std makes each update a larger KL (1 collapse in 8 annealed runs, 0 in 8 constant)",
    ),
    _int(
        "planner.std_anneal_phases",
        "planner",
        1000,
        "planner phases over which the std is annealed (warm start included)",
        1,
    ),
    _choice(
        "planner.angles",
        "planner",
        "scaled",
        "angles of the goal space (maze-rigid, maze-snake): raw coordinates, wrapped (short-way midpoints), "
        "or wrapped with each dim's std divided by its distance weight",
        ANGLE_MODES,
        why="SGT-PG alone on maze-rigid, one seed, first 20 four-rooms test tasks: raw 0.00 free finest "
        "paths from ~40 phases on, wrapped 0.00 after 100 phases, scaled 0.25-0.35 over the first 100 "
        "(`benchmarks/planners_maze.py --agents rigid --phases 100 --eval-every 25 --angles ...`); no "
        "angles in maze-point, where all three are the same",
    ),
    _float("planner.lr", "planner", 0.005, "pi_p's Adam learning rate (paper 4.1)", 0.0, lo_open=True),
    _float(
        "planner.clip", "planner", 0.2, "PPO's clip range (paper 4.1)", 0.0, 1.0, lo_open=True, hi_open=True
    ),
    _int("planner.epochs", "planner", 4, "PPO epochs per planner phase", 1),
    _int("planner.num_samples", "planner", 16, "trees sampled per task; their mean cost is the baseline", 1),
    _float(
        "planner.max_grad_norm",
        "planner",
        0.5,
        "gradient-norm clip of pi_p (not in the paper: without it PPO diverged on four-rooms within ~100 phases)",
        0.0,
        lo_open=True,
        optional=True,
    ),
    _float(
        "planner.target_kl",
        "planner",
        None,
        "stop a phase's PPO epochs once the approximate KL exceeds this",
        0.0,
        lo_open=True,
        optional=True,
    ),
    _float(
        "planner.max_kl",
        "planner",
        None,
        "undo a PPO update whose approximate KL exceeds this",
        0.0,
        lo_open=True,
        optional=True,
    ),
    _choice(
        "planner.mean",
        "planner",
        "leaky",
        "pi_p's mean: free (midpoint + MLP output, samples clipped into the box; reference code), squashed "
        "into the goal box by a tanh, or leaky: free inside the box, 1 % of the overshoot outside it",
        MEAN_MODES,
        why="on VALIDATION tasks (planner only, 1000 phases, seeds 0-3, docs/planner_probe): no leaky run "
        "collapsed, 1 of 8 free ones did (a free mean past the border puts every clipped sample on one point: "
        "no advantage, no way back); four-rooms 0.87-0.98 collision-free plans, 0.70-0.79 followed by an "
        "oracle agent (free: 0.75-0.92 and 0.66-0.71 where it did not collapse), u-maze 0.97-1.00 and 0.84-0.99 "
        "(free 0.97-1.00, 0.88-0.98); a tanh-squashed mean did not collapse either but its plans were harder "
        "to follow (0.32-0.41, 0.55-0.62); kept by the full-loop decision check (docs/planner_mean_decision, "
        "its rule fixed before it ran: the higher mean over four-rooms and u-maze of the IQM final validation "
        "success, 200k env steps, 5 seeds each): leaky 0.581 and 0.855 (0.718), free 0.534 and 0.797 (0.666), "
        "95 % intervals overlapping on both mazes; on spiral's validation tasks the free mean's planner collapses",
    ),
]
_COST_MODEL = [
    _sizes("cost_model.hidden", "cost_model", [64, 64], "tau_hat's hidden layers"),
    _float("cost_model.lr", "cost_model", 1e-3, "tau_hat's Adam learning rate", 0.0, lo_open=True),
    _int("cost_model.capacity", "cost_model", 200_000, "D_tau's capacity (tuples)", 1),
    _int(
        "cost_model.init_euclidean",
        "cost_model",
        50_000,
        "Euclidean tuples D_tau starts with (paper 4.1: 50k)",
        0,
    ),
    _int("cost_model.fit_steps", "cost_model", 50, "tau_hat gradient steps per iteration", 1),
    _int("cost_model.batch_size", "cost_model", 256, "tau_hat's batch size", 1),
]
_EVALUATION = [
    _A["eval_interval"],
    _A["eval_every_env_steps"],
    _A["eval_num_tasks"],
    _int(
        "eval_tree_tasks", "copilot", 3, "fixed test tasks whose sub-goal trees are saved per evaluation", 0
    ),
    _float(
        "eval_rrt_reference_s",
        "copilot",
        0.0,
        "RRT*'s time per task for the paths/*_vs_rrt metrics (computed once per env, cached; 0: none)",
        0.0,
    ),
    _A["eval_action"],
]
_SAC = list(agent_settings.LEARNER)

PRESET_NAMES = ("default", "paper_literal")
_PRESET = [
    _choice(
        "preset",
        "copilot",
        None,
        "a named set of readings applied before every other setting: the measured defaults, or the "
        "paper's reading",
        PRESET_NAMES,
        optional=True,
    )
]

GROUPS: dict[str, list[Setting]] = {
    "preset": _PRESET,
    "tree and curriculum": _TREE,
    "alpha schedule fields (sweep specs)": _ALPHA_FIELDS,
    "sub-task traversal": _TRAVERSAL,
    "planner": _PLANNER,
    "cost model tau_hat": _COST_MODEL,
    "evaluation": _EVALUATION,
    "SAC": _SAC,
}
SETTINGS: dict[str, Setting] = {s.key: s for group in GROUPS.values() for s in group}


def defaults(target: str) -> dict[str, Any]:
    """`{field: default}` of one target's settings (`defaults("planner")`: pi_p's settings)."""
    return {s.field: s.default for s in SETTINGS.values() if s.target == target}


# ------------------------------------------------------------------------------------------ presets
# The measured reading of every paper ambiguity (the settings with a `why`), and agent_collision_penalty
# because a preset may change it.
_DEFAULT_READINGS: dict[str, Any] = {
    s.key: s.default for s in SETTINGS.values() if s.why and s.target in ("copilot", "agent", "training")
}
_DEFAULT_READINGS["agent_collision_penalty"] = SETTINGS["agent_collision_penalty"].default
_DEFAULT_READINGS["planner"] = {
    k: SETTINGS[f"planner.{k}"].default for k in ("std", "noise", "std_final", "angles", "mean")
}

PRESETS: dict[str, dict[str, Any]] = {
    # The measured defaults again (undoes another preset; a sweep axis value).
    "default": _DEFAULT_READINGS,
    # The paper's reading of every one of them (where it is silent: the public reference code's).
    "paper_literal": {
        **_DEFAULT_READINGS,
        "after_failure": "continue",
        "subtask_reward": "halving",
        "traversal_tree": "sampled",
        "failed_subtask_cost": "end_state",
        "planner_warm_start": 0,
        # The reference code's planner noise: a fixed absolute std.
        "planner": {"std": 0.05, "noise": "absolute", "std_final": None, "angles": "raw", "mean": "free"},
        # The agent's SAC settings (initial temperature, input) stay those every baseline gets, so that
        # this preset isolates the paper's readings of CO-PILOT itself. (The paper's "SAC with its
        # default hyperparameters" is initial_alpha 1.0 and agent_input state_goal: set them to see it.)
    },
}
assert tuple(PRESETS) == PRESET_NAMES

# CO-PILOT, its readings (the preset) held fixed: the learner's space plus the planner's learning rate.
SEARCH_SPACE: dict[str, dict] = {
    **agent_settings.LEARNER_SEARCH_SPACE,
    "planner.lr": {"float": [1e-3, 1e-2], "log": True},
}

# ------------------------------------------------------------------------------------------ metrics
# What a CO-PILOT run logs that a sweep may optimise or stop on; `<k>` is a tree layer (0..K).
# What its runs are labelled by (progress lines, MLflow tags, the report's configuration names).
LABELS = {"K": "tree_depth", "b": "repetitions", "alpha_schedule": "alpha_schedule"}

# An RLlib learner: on the trial's GPU share when the spec asks for one (resources.gpus_per_trial).
GPU_LEARNER = True
# Seeds of one configuration can share one trial and one stacked update (a spec's seeds_per_trial).
SEED_STACK = True

METRICS: tuple[str, ...] = (
    *keys.TREE_AGENT_EVAL_METRICS,  # validation figures for searchers, test figures reported
    keys.ALPHA,
    keys.PLANNER_COST_LAYER + "<k>",
    keys.PLANNER_APPROX_KL_MAX,
    keys.PLANNER_NONFINITE_SKIPPED,
    keys.AGENT_STEPS_LAYER + "<k>",
    keys.AGENT_SUCCESS_LAYER + "<k>",
    keys.DTAU_SIZE,
    keys.COST_MODEL_LOSS,
    keys.ENV_STEPS,
    "env_runners/episode_return_mean",  # RLlib's
    *keys.PATH_METRICS,  # its finest paths scored as a motion planner's (copilot_ray.planning.path_metrics)
)


# ------------------------------------------------------------------------- from values to a config
def alpha_schedule_from(values: Mapping[str, Any]) -> Any:
    """The alpha schedule (preset name or dict) that flat `values` ask for; None: the default.

    `alpha_schedule.kind` builds the schedule from the dotted fields alone; otherwise the dotted fields
    override `alpha_schedule` (or its default preset).
    """
    dotted = {k.split(".", 1)[1]: v for k, v in values.items() if k.startswith("alpha_schedule.")}
    whole = values.get("alpha_schedule")
    if not dotted:
        return whole
    if "kind" in dotted:
        return dotted
    base = AlphaSchedule.from_dict(whole if whole is not None else SETTINGS["alpha_schedule"].default)
    return {**base.to_dict(), **dotted}


def as_logged(values: Mapping[str, Any]) -> dict[str, Any]:
    """Effective flat `values` as a run's params hold them: the alpha schedule as the fields of the
    schedule it resolves to (`alpha_schedule.kind`, `.start`, ...), not as its preset's name."""
    out = {k: v for k, v in values.items() if k != "alpha_schedule" and not k.startswith("alpha_schedule.")}
    given = {k: v for k, v in values.items() if k.startswith("alpha_schedule.") and v is not None}
    schedule = alpha_schedule_from({"alpha_schedule": values.get("alpha_schedule"), **given})
    fields = AlphaSchedule.from_dict(schedule if schedule is not None else SETTINGS["alpha_schedule"].default)
    out.update({f"alpha_schedule.{k}": v for k, v in fields.to_dict().items()})
    return out


def effective_values(values: Mapping[str, Any]) -> dict[str, Any]:
    """Every top-level setting a run of flat `values` uses: defaults, then the preset, then `values`."""
    out = {key: s.default for key, s in SETTINGS.items() if "." not in key}
    out.update({k: v for k, v in PRESETS.get(values.get("preset") or "default", {}).items() if "." not in k})
    out.update({k: v for k, v in values.items() if "." not in k})
    return out


def max_iteration_env_steps(values: Mapping[str, Any]) -> int:
    """The most env steps one iteration can take (every sub-task of every tree runs to its limit):
    task_batch_size x b x the sub-tasks' step limits summed over the layers K..0."""
    v = effective_values(values)
    depth, tau = int(v["tree_depth"]), int(v["tau_max"])
    per_tree = sum(
        2**k * (tau * 2 ** (depth - k) if v["step_limit"] == "scaled" else tau) for k in range(depth + 1)
    )
    return int(v["task_batch_size"]) * int(v["repetitions"]) * per_tree


def max_env_steps_past_budget(values: Mapping[str, Any]) -> int:
    """The most env steps a run can take past its env-step budget or an evaluation point: the iteration
    that reaches one ends after the repetition that does, so one repetition's worth (task_batch_size
    trees), less one."""
    return max_iteration_env_steps(values) // int(effective_values(values)["repetitions"]) - 1


def combination_problems(values: Mapping[str, Any]) -> list[tuple[tuple[str, ...], Any, str]]:
    """Values valid one by one that clash together: (the keys involved, their values, why)."""
    out = agent_settings.combination_problems(values)
    if "alpha_schedule" in values and "alpha_schedule.kind" in values:
        out.append(
            (
                ("alpha_schedule", "alpha_schedule.kind"),
                values["alpha_schedule.kind"],
                "give either alpha_schedule (preset or mapping) or alpha_schedule.kind with its fields, not both",
            )
        )
    elif any(k.startswith("alpha_schedule") for k in values):
        try:
            AlphaSchedule.from_dict(alpha_schedule_from(values))
        except (ValueError, TypeError) as err:
            involved = tuple(k for k in values if k.startswith("alpha_schedule"))
            out.append(
                (
                    involved,
                    {k: values[k] for k in involved},
                    f"these alpha_schedule keys do not form a schedule: {err}",
                )
            )
    return out


# ----------------------------------------------------------------------- the settings page's tables
def _paper_value(setting: Setting) -> str:
    paper = PRESETS["paper_literal"]
    if setting.target == "planner":
        return markdown_value(paper.get("planner", {}).get(setting.field, setting.default))
    return markdown_value(paper.get(setting.key, setting.default))


def readings_table() -> str:
    """The "Readings of the paper" table (docs/settings.md): the settings with a measured reason for their
    default."""
    rows = [
        "| setting | `paper_literal` | default | why the default (K = 5; single-seed probes on four-rooms, see "
        "below, which read the test tasks before validation sets existed; after_failure's, planner_warm_start's, "
        "planner.std_final's and planner.mean's on validation tasks) |",
        "|---|---|---|---|",
    ]
    rows += [
        f"| `{s.key}` | {_paper_value(s)} | {markdown_value(s.default)} | {s.why} |"
        for s in SETTINGS.values()
        if s.why
    ]
    return "\n".join(rows)


def settings_table() -> str:
    """The table of every setting, by concern (docs/settings.md)."""
    rows = ["| setting | default | allowed | what |", "|---|---|---|---|"]
    for group, settings in GROUPS.items():
        rows.append(f"| **{group}** | | | |")
        for s in settings:
            field_of_schedule = s.target == "alpha_schedule" and s.key != "alpha_schedule"
            default = "(the schedule's)" if field_of_schedule else markdown_value(s.default)
            rows.append(f"| `{s.key}` | {default} | {s.rule} | {s.doc} |")
    return "\n".join(rows)


_GENERATED = "(generated: python -m copilot_ray.algorithms.copilot.settings --write docs/settings.md)"
README_TABLES = {
    f"<!-- readings-table:begin {_GENERATED} -->": ("<!-- readings-table:end -->", readings_table),
    f"<!-- settings-table:begin {_GENERATED} -->": ("<!-- settings-table:end -->", settings_table),
}


def render_readme(text: str) -> str:
    """`text` (a page holding the tables' markers: docs/settings.md) with both generated tables replaced by
    the current ones."""
    for begin, (end, table) in README_TABLES.items():
        text = replace_between(text, begin, end, table())
    return text


if __name__ == "__main__":
    import argparse
    from pathlib import Path

    parser = argparse.ArgumentParser(
        description="Print CO-PILOT's settings tables, or write them into a page (docs/settings.md)."
    )
    parser.add_argument("--write", metavar="PAGE", help="replace the tables between the markers in this file")
    args = parser.parse_args()
    if args.write:
        path = Path(args.write)
        path.write_text(render_readme(path.read_text()))
        print(f"wrote the settings tables into {path}")
    else:
        print(readings_table() + "\n\n" + settings_table())
