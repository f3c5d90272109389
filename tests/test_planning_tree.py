"""Index layout of batched sub-goal trees."""

import numpy as np
import pytest
import torch

from copilot_ray.planning import (
    SubgoalTree,
    depth_of,
    empty_tree,
    layer_indices,
    layer_path,
    layer_segments,
    new_layer_indices,
    parent_indices,
    tree_size,
)

torch.set_num_threads(1)


@pytest.mark.parametrize("K", [1, 2, 3, 4])
def test_indices_for_each_depth(K):
    T = 2**K
    assert tree_size(K) == T + 1
    assert layer_indices(K, 0).tolist() == [0, T]
    assert layer_indices(K, K).tolist() == list(range(T + 1))
    seen = {0, T}
    for k in range(1, K + 1):
        idx = layer_indices(K, k)
        assert idx.tolist() == [j * 2 ** (K - k) for j in range(2**k + 1)]
        new = new_layer_indices(K, k)
        assert len(new) == 2 ** (k - 1)
        # the new midpoints are exactly the indices of layer k not in layer k-1
        assert set(new.tolist()) == set(idx.tolist()) - set(layer_indices(K, k - 1).tolist())
        assert not (set(new.tolist()) & seen)
        seen |= set(new.tolist())
        left, right = parent_indices(K, k)
        prev = set(layer_indices(K, k - 1).tolist())
        assert set(left.tolist()) <= prev and set(right.tolist()) <= prev
        np.testing.assert_array_equal((left + right) // 2, new)
        np.testing.assert_array_equal(right - left, 2 ** (K - k + 1))
    assert seen == set(range(T + 1))  # every node is filled by exactly one layer


def test_explicit_depth_3():
    assert new_layer_indices(3, 1).tolist() == [4]
    assert new_layer_indices(3, 2).tolist() == [2, 6]
    assert new_layer_indices(3, 3).tolist() == [1, 3, 5, 7]
    left, right = parent_indices(3, 2)
    assert left.tolist() == [0, 4] and right.tolist() == [4, 8]


@pytest.mark.parametrize("K", [1, 2, 3, 4])
def test_layer_path_and_segments(K):
    B, d = 3, 2
    trees = np.arange(B * (2**K + 1) * d, dtype=np.float32).reshape(B, 2**K + 1, d)
    for k in range(K + 1):
        path = layer_path(trees, K, k)
        assert path.shape == (B, 2**k + 1, d)
        np.testing.assert_array_equal(path[:, 0], trees[:, 0])
        np.testing.assert_array_equal(path[:, -1], trees[:, -1])
        a, b = layer_segments(trees, K, k)
        assert a.shape == b.shape == (B * 2**k, d)
        np.testing.assert_array_equal(a.reshape(B, 2**k, d), path[:, :-1])
        np.testing.assert_array_equal(b.reshape(B, 2**k, d), path[:, 1:])
    assert depth_of(trees) == K


def test_empty_tree_and_object_wrapper():
    starts = np.array([[0.0, 0.0], [1.0, 1.0]])
    goals = np.array([[1.0, 0.0], [0.0, 1.0]])
    t = empty_tree(starts, goals, 2)
    assert t.shape == (2, 5, 2)
    np.testing.assert_array_equal(t[:, 0], starts)
    np.testing.assert_array_equal(t[:, -1], goals)
    assert np.isnan(t[:, 1:-1]).all()
    tree = SubgoalTree(2)
    assert tree.size == 5 and tree.horizon == 4
    assert tree.layer_indices(1).tolist() == [0, 2, 4]


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2"])
def test_invalid_depth(bad):
    with pytest.raises(ValueError, match="K must be an integer >= 1"):
        tree_size(bad)
    with pytest.raises(ValueError, match="K must be an integer >= 1"):
        SubgoalTree(bad)


def test_invalid_layer_and_shapes():
    with pytest.raises(ValueError, match="layer k"):
        layer_indices(3, 4)
    with pytest.raises(ValueError, match="layer k"):
        new_layer_indices(3, 0)
    with pytest.raises(ValueError, match="2\\^K \\+ 1"):
        depth_of(np.zeros((1, 6, 2)))
    with pytest.raises(ValueError, match="shape"):
        empty_tree(np.zeros((2, 2)), np.zeros((3, 2)), 2)
