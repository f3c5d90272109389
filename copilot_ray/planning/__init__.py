"""Planning for CO-PILOT: sub-goal trees, the planner pi_p, segment costs, D_tau / tau_hat, alpha schedules.

Pure numpy / torch; no RLlib and no environment import. Environment hooks (``segments_collide``,
``goal_distance``) are passed in as plain callables.
"""

from .alpha_schedule import PRESETS as ALPHA_PRESETS
from .alpha_schedule import AlphaClock, AlphaSchedule
from .construction import ConstructionResult, construct_trees
from .planner import SubgoalPlanner, group_baseline
from .segment_cost import SegmentCost, euclidean_distance, tree_cost, tree_segments
from .subgoal_tree import (
    SubgoalTree,
    depth_of,
    empty_tree,
    layer_indices,
    layer_path,
    layer_segments,
    new_layer_indices,
    parent_indices,
    path_indices,
    tree_size,
)
from .time_cost import TimeCostDataset, TimeCostModel

__all__ = [
    "ALPHA_PRESETS",
    "AlphaClock",
    "AlphaSchedule",
    "ConstructionResult",
    "SegmentCost",
    "SubgoalPlanner",
    "SubgoalTree",
    "TimeCostDataset",
    "TimeCostModel",
    "construct_trees",
    "depth_of",
    "empty_tree",
    "euclidean_distance",
    "group_baseline",
    "layer_indices",
    "layer_path",
    "layer_segments",
    "new_layer_indices",
    "parent_indices",
    "path_indices",
    "tree_cost",
    "tree_segments",
    "tree_size",
]
