"""Planning for CO-PILOT: sub-goal trees, the planner pi_p, segment costs, D_tau / tau_hat, alpha schedules.

Pure numpy / torch; no RLlib and no environment import. Environment hooks (``segments_collide``,
``goal_distance``) are passed in as plain callables.

The names below are loaded on first use (PEP 562), so that importing one light submodule (the alpha
schedule, which every command line parses) does not import torch: a refused flag or spec answers in
about half the time.
"""

from importlib import import_module

_HOMES = {
    "ALPHA_PRESETS": ("alpha_schedule", "PRESETS"),
    "AlphaClock": ("alpha_schedule", "AlphaClock"),
    "AlphaSchedule": ("alpha_schedule", "AlphaSchedule"),
    "ConstructionResult": ("construction", "ConstructionResult"),
    "construct_trees": ("construction", "construct_trees"),
    "SubgoalPlanner": ("planner", "SubgoalPlanner"),
    "group_baseline": ("planner", "group_baseline"),
    "SegmentCost": ("segment_cost", "SegmentCost"),
    "euclidean_distance": ("segment_cost", "euclidean_distance"),
    "tree_cost": ("segment_cost", "tree_cost"),
    "tree_segments": ("segment_cost", "tree_segments"),
    **{
        name: ("subgoal_tree", name)
        for name in (
            "SubgoalTree",
            "depth_of",
            "empty_tree",
            "layer_indices",
            "layer_path",
            "layer_segments",
            "new_layer_indices",
            "parent_indices",
            "path_indices",
            "tree_size",
        )
    },
    "TimeCostDataset": ("time_cost", "TimeCostDataset"),
    "TimeCostModel": ("time_cost", "TimeCostModel"),
}

__all__ = sorted(_HOMES)


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{home[0]}"), home[1])
    globals()[name] = value  # the next lookup is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOMES))
