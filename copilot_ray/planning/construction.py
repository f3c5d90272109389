"""Top-down construction of sub-task trees (paper Algorithm 1), batched over tasks.

For k = 1..K:

1. (``train=True``) draw ``num_samples`` trees per task from the current policy, layers 1..k, evaluate
   ``J^k`` (Eq. 8 summed over layers 0..k, the curriculum of Sec. 3.3) and run one PPO update of the
   planner on them, the baseline being the mean cost of the task's repeated samples. Repeated
   ``updates_per_layer`` times with fresh samples.
2. Sample layer k of the output tree (one tree per task; the mean with ``deterministic=True``). Layers
   < k of the output tree were sampled before, by the policy as it was then: exactly Algorithm 1.

All tasks and all their samples go through the policy and the cost function as one batch
(``B * num_samples`` trees); there is no Python loop over tasks or segments.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .planner import SubgoalPlanner, _as_rng
from .segment_cost import tree_cost
from .subgoal_tree import check_depth, empty_tree

__all__ = ["ConstructionResult", "construct_trees"]


@dataclass
class ConstructionResult:
    """Output of :func:`construct_trees`.

    Attributes:
        trees: ``[B, 2^K + 1, d]`` float32 sub-goal trees, every layer filled.
        layer_costs: ``[B, K + 1]`` path cost of each layer of the output trees under ``cost_fn``.
        stats: flat float metrics, keys:
            ``cost_layer_<k>`` (k = 0..K) mean path cost of layer k of the output trees (the metric
            ``copilot/planner/cost_layer_<k>``); ``cost_total`` their sum (Eq. 8);
            with ``train=True`` and k = 1..K: ``train_cost_J<k>`` mean J^k of the training samples before
            the update, ``train_cost_layer_<k>`` mean layer-k path cost of those samples,
            ``loss_layer_<k>``, ``approx_kl_layer_<k>``, ``clip_fraction_layer_<k>`` of the last update;
            ``time_s`` wall time of the whole construction.
    """

    trees: np.ndarray
    layer_costs: np.ndarray
    stats: dict[str, float] = field(default_factory=dict)


def _train_layer(
    planner: SubgoalPlanner,
    starts: np.ndarray,
    goals: np.ndarray,
    K: int,
    k: int,
    cost_fn: Callable,
    num_samples: int,
    rng: np.random.Generator,
) -> dict[str, float]:
    B = starts.shape[0]
    rep_starts = np.repeat(starts, num_samples, axis=0)
    rep_goals = np.repeat(goals, num_samples, axis=0)
    group_ids = np.repeat(np.arange(B), num_samples)
    samples = planner.sample(rep_starts, rep_goals, depth=K, upto_layer=k, rng=rng)
    layer_costs, J = tree_cost(samples, K, k, cost_fn)
    stats = {"train_cost_J": float(J.mean()), "train_cost_layer": float(layer_costs[:, k].mean())}
    if planner.augment_reversed:
        # Every sample again with start and goal swapped (the reference code's augmentation). The
        # reversed tree is the same node array read backwards; its cost is re-evaluated because
        # tau_hat need not be symmetric. A reversed task is its own group (its own baseline).
        rev = samples[:, ::-1].copy()
        _, J_rev = tree_cost(rev, K, k, cost_fn)
        samples = np.concatenate([samples, rev])
        J = np.concatenate([J, J_rev])
        group_ids = np.concatenate([group_ids, group_ids + B])
    stats.update(planner.update(samples, J, upto_layer=k, group_ids=group_ids))
    return stats


def construct_trees(
    planner: SubgoalPlanner,
    starts,
    goals,
    depth: int | None = None,
    cost_fn: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    *,
    num_samples: int = 16,
    train: bool = True,
    deterministic: bool = False,
    updates_per_layer: int = 1,
    rng=None,
) -> ConstructionResult:
    """Algorithm 1 for a mini-batch of tasks.

    Args:
        planner: the policy pi_p (updated in place when ``train``).
        starts, goals: ``[B, d]`` task endpoints.
        depth: tree depth K (default: the planner's depth).
        cost_fn: batched segment cost ``c(a, b) -> [N]`` (e.g. a :class:`SegmentCost`); required when
            ``train`` (and used to report the output trees' costs).
        num_samples: repeated trees per task for each update (the baseline group size).
        train: run the planner updates (False: only sample, e.g. for evaluation).
        deterministic: output trees from the policy mean instead of samples.
        updates_per_layer: PPO updates (each on fresh samples) per layer.
        rng: numpy Generator or seed for all sampling noise.
    """
    K = planner.depth if depth is None else check_depth(depth)
    starts = np.asarray(starts, dtype=np.float32)
    goals = np.asarray(goals, dtype=np.float32)
    if train and cost_fn is None:
        raise ValueError("construct_trees(train=True) needs a cost_fn")
    if train and int(num_samples) < 2:
        raise ValueError(f"num_samples must be >= 2 to form a baseline, got num_samples={num_samples!r}")
    rng = _as_rng(rng)
    t0 = time.perf_counter()
    trees = empty_tree(starts, goals, K)
    stats: dict[str, float] = {}
    for k in range(1, K + 1):
        if train:
            for _ in range(int(updates_per_layer)):
                s = _train_layer(planner, starts, goals, K, k, cost_fn, int(num_samples), rng)
            stats[f"train_cost_J{k}"] = s["train_cost_J"]
            stats[f"train_cost_layer_{k}"] = s["train_cost_layer"]
            stats[f"loss_layer_{k}"] = s["loss"]
            stats[f"approx_kl_layer_{k}"] = s["approx_kl"]
            stats[f"clip_fraction_layer_{k}"] = s["clip_fraction"]
            stats[f"epochs_layer_{k}"] = s["epochs_run"]
            stats["nonfinite_skipped"] = stats.get("nonfinite_skipped", 0.0) + s["nonfinite_skipped"]
            stats["rolled_back"] = stats.get("rolled_back", 0.0) + s["rolled_back"]
        planner.extend(trees, k, deterministic=deterministic, rng=rng)
    if cost_fn is not None:
        layer_costs, total = tree_cost(trees, K, K, cost_fn)
        for k in range(K + 1):
            stats[f"cost_layer_{k}"] = float(layer_costs[:, k].mean())
        stats["cost_total"] = float(total.mean())
    else:
        layer_costs = np.full((starts.shape[0], K + 1), np.nan)
    stats["time_s"] = time.perf_counter() - t0
    return ConstructionResult(trees=trees, layer_costs=layer_costs, stats=stats)
