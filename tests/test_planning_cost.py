"""Segment cost (Eq. 11) and tree cost J^k (Eq. 8 up to layer k)."""

import numpy as np
import pytest
import torch

from copilot_ray.planning import SegmentCost, euclidean_distance, tree_cost

torch.set_num_threads(1)


def _hand_tree():
    # depth 2 tree on a line with a detour: nodes 0..4
    return np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0], [2.0, 0.0]]])


def test_tree_cost_euclidean_hand_made():
    trees = _hand_tree()
    cost = SegmentCost(alpha=1.0)
    layer_costs, total = tree_cost(trees, 2, 2, cost)
    # layer 0: (0,0)->(2,0) = 2; layer 1: (0,0)->(1,1)->(2,0) = 2*sqrt2; layer 2: 1+1+1+1 = 4
    np.testing.assert_allclose(layer_costs[0], [2.0, 2 * np.sqrt(2), 4.0])
    np.testing.assert_allclose(total, [6.0 + 2 * np.sqrt(2)])
    lc1, j1 = tree_cost(trees, 2, 1, cost)
    np.testing.assert_allclose(lc1[0], [2.0, 2 * np.sqrt(2)])
    np.testing.assert_allclose(j1, [2.0 + 2 * np.sqrt(2)])
    # the method form and the K-from-shape default agree
    np.testing.assert_allclose(cost.tree_cost(trees, upto_layer=1)[1], j1)


def test_tree_cost_with_collisions_and_time_cost():
    trees = _hand_tree()

    def collide(a, b):  # any segment touching x = 2 "collides"
        return (a[:, 0] == 2.0) | (b[:, 0] == 2.0)

    def tau(a, b):  # a time cost of twice the distance
        return 2.0 * euclidean_distance(a, b)

    cost = SegmentCost(alpha=0.25, time_cost=tau, segments_collide=collide, collision_penalty=10.0)
    layer_costs, total = tree_cost(trees, 2, 2, cost)
    scale = 0.25 + 0.75 * 2.0
    # layer 0: 1 colliding segment; layer 1: 1 of 2; layer 2: 2 of 4 ((1,1)->(2,1), (2,1)->(2,0))
    expected = [2.0 * scale + 10, 2 * np.sqrt(2) * scale + 10, 4.0 * scale + 20]
    np.testing.assert_allclose(layer_costs[0], expected)
    np.testing.assert_allclose(total, [sum(expected)])


def test_tree_cost_batched_matches_rows():
    rng = np.random.default_rng(0)
    trees = rng.uniform(size=(7, 9, 3))
    cost = SegmentCost(alpha=1.0)
    lc, total = tree_cost(trees, 3, 3, cost)
    for i in range(7):
        lci, _ = tree_cost(trees[i : i + 1], 3, 3, cost)
        np.testing.assert_allclose(lc[i], lci[0])
    path3 = np.linalg.norm(np.diff(trees, axis=1), axis=-1).sum(1)
    np.testing.assert_allclose(lc[:, 3], path3)


def test_segment_cost_validation():
    with pytest.raises(ValueError, match="alpha"):
        SegmentCost(alpha=1.5)
    cost = SegmentCost(alpha=0.5)
    with pytest.raises(ValueError, match="time_cost"):
        cost(np.zeros((1, 2)), np.ones((1, 2)))
    cost.alpha = -0.1
    with pytest.raises(ValueError, match="alpha"):
        cost(np.zeros((1, 2)), np.ones((1, 2)))
    with pytest.raises(ValueError, match="collision_cost='sometimes'"):
        SegmentCost(collision_cost="sometimes")
    with pytest.raises(ValueError, match="collision_lengths"):
        SegmentCost(collision_cost="length")


def test_length_collision_cost_charges_length_in_collision():
    trees = _hand_tree()

    def collide(a, b):  # segments with an end at x = 2 "collide"
        return (a[:, 0] == 2.0) | (b[:, 0] == 2.0)

    def lengths(a, b):  # ... with half of their length
        return np.where(collide(a, b), 0.5 * euclidean_distance(a, b), 0.0)

    cost = SegmentCost(
        alpha=1.0,
        segments_collide=collide,
        collision_penalty=100.0,
        collision_cost="length",
        collision_lengths=lengths,
    )
    layer_costs, _ = tree_cost(trees, 2, 2, cost)
    # Each colliding segment: 100 * (length in collision + 0.1). Layer 0: 2 + 100 * (1 + 0.1); layer 1:
    # (0,0)->(1,1) free, (1,1)->(2,0) half of sqrt2 in collision; layer 2: (1,1)->(2,1) and (2,1)->(2,0)
    # collide, half of each.
    expected = [
        2.0 + 110.0,
        2 * np.sqrt(2) + 100.0 * (0.5 * np.sqrt(2) + 0.1),
        4.0 + 100.0 * (0.5 + 0.5 + 0.2),
    ]
    np.testing.assert_allclose(layer_costs[0], expected)
    assert set(cost.components(trees[0, :2], trees[0, 1:3])) >= {"collides", "collision_length"}
