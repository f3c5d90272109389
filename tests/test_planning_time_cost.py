"""D_tau ring buffer and the time-cost regression model."""

import numpy as np
import pytest
import torch

from copilot_ray.planning import TimeCostDataset, TimeCostModel, euclidean_distance

torch.set_num_threads(1)


def _tuples(n, start=0, d=2):
    s = np.full((n, d), 0.0) + np.arange(start, start + n)[:, None]
    return s, s + 1.0, np.arange(start, start + n, dtype=float)


def test_ring_buffer_bounds_and_wrap_around():
    ds = TimeCostDataset(goal_dim=2, capacity=5, recent_fraction=0.0)
    assert len(ds) == 0
    ds.add(*_tuples(3))
    assert len(ds) == 3
    ds.add(*_tuples(4, start=3))  # 7 added, capacity 5: the two oldest are gone
    assert len(ds) == 5 and ds.num_added == 7
    s, e, c = ds.arrays()
    assert c.tolist() == [2, 3, 4, 5, 6]  # oldest first, across the wrap
    np.testing.assert_array_equal(e - s, 1.0)
    ds.add(*_tuples(12, start=100))  # more than the capacity in one call
    assert len(ds) == 5 and ds.num_added == 19
    assert ds.arrays()[2].tolist() == [107, 108, 109, 110, 111]
    _, _, cs = ds.sample(200, np.random.default_rng(0))
    assert set(cs.tolist()) <= {107, 108, 109, 110, 111}


def test_recent_fraction_sampling():
    ds = TimeCostDataset(goal_dim=1, capacity=1000, recent_fraction=0.5, recent_window=10)
    ds.add(np.zeros((990, 1)), np.zeros((990, 1)), np.zeros(990))
    ds.add(np.zeros((10, 1)), np.zeros((10, 1)), np.ones(10))
    _, _, c = ds.sample(2000, np.random.default_rng(0))
    assert 0.45 < c.mean() < 0.55  # half the batch from the newest 10 tuples (plus ~1% by chance)


def test_init_euclidean_and_validation():
    ds = TimeCostDataset(goal_dim=2, capacity=1000)
    ds.init_euclidean(500, low=0.0, high=1.0, rng=np.random.default_rng(0))
    s, e, c = ds.arrays()
    assert len(ds) == 500 and (s >= 0).all() and (e <= 1).all()
    np.testing.assert_allclose(c, euclidean_distance(s, e), rtol=1e-5)
    with pytest.raises(ValueError, match="capacity"):
        TimeCostDataset(2, capacity=0)
    with pytest.raises(ValueError, match="recent_fraction"):
        TimeCostDataset(2, recent_fraction=2.0)
    with pytest.raises(ValueError, match="empty"):
        TimeCostDataset(2).sample(3)


def test_dataset_state_dict_round_trip():
    ds = TimeCostDataset(goal_dim=2, capacity=5)
    ds.add(*_tuples(7))
    other = TimeCostDataset(goal_dim=2, capacity=99)
    other.load_state_dict(ds.state_dict())
    assert other.capacity == 5 and len(other) == 5 and other.num_added == 7
    for x, y in zip(ds.arrays(), other.arrays(), strict=True):
        np.testing.assert_array_equal(x, y)
    other.add(*_tuples(1, start=50))
    ds.add(*_tuples(1, start=50))
    np.testing.assert_array_equal(ds.arrays()[2], other.arrays()[2])


def test_model_fit_learns_twice_euclidean():
    rng = np.random.default_rng(0)
    model = TimeCostModel(2, low=0.0, high=1.0, step_distance=0.05, seed=0, recent_fraction=0.0)
    a = rng.uniform(size=(5000, 2))
    b = rng.uniform(size=(5000, 2))
    steps = 2.0 * euclidean_distance(a, b) / 0.05  # measured in steps: 2 * distance
    model.add_steps(a, b, steps)
    first = model.fit(num_steps=20, batch_size=256, rng=rng)
    last = model.fit(num_steps=400, batch_size=256, rng=rng)
    assert last < 0.5 * first
    ta, tb = rng.uniform(size=(1000, 2)), rng.uniform(size=(1000, 2))
    truth = 2.0 * euclidean_distance(ta, tb)
    pred = model.predict(ta, tb)
    assert pred.shape == (1000,) and (pred > 0).all()
    assert np.mean(np.abs(pred - truth)) < 0.1 * truth.mean()


def test_model_state_dict_round_trip():
    rng = np.random.default_rng(1)
    model = TimeCostModel(2, low=0.0, high=1.0, seed=0)
    model.init_euclidean(2000, rng=rng)
    model.fit(num_steps=5, batch_size=64, rng=rng)
    other = TimeCostModel(2, low=0.0, high=1.0, seed=1)
    other.load_state_dict(model.state_dict())
    x, y = rng.uniform(size=(10, 2)), rng.uniform(size=(10, 2))
    np.testing.assert_allclose(other.predict(x, y), model.predict(x, y))
    assert len(other.dataset) == 2000
    # identical continued training: optimizer state was restored too
    model.fit(num_steps=3, batch_size=64, rng=np.random.default_rng(7))
    other.fit(num_steps=3, batch_size=64, rng=np.random.default_rng(7))
    np.testing.assert_allclose(other.predict(x, y), model.predict(x, y), rtol=1e-5)
