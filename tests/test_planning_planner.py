"""The planner pi_p, its PPO update and the top-down construction (Algorithm 1)."""

import math

import numpy as np
import pytest
import torch

from copilot_ray.envs.maze.geometry import Obstacles
from copilot_ray.planning import (
    SegmentCost,
    SubgoalPlanner,
    construct_trees,
    group_baseline,
    layer_segments,
    new_layer_indices,
    parent_indices,
    tree_cost,
)

torch.set_num_threads(1)


def _tasks(B, d=2, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.1, 0.9, size=(B, d)), rng.uniform(0.1, 0.9, size=(B, d))


def test_initial_mean_is_midpoint_and_sampling_fills_layers():
    planner = SubgoalPlanner(2, 3, low=0.0, high=1.0, seed=0)
    starts, goals = _tasks(4)
    mean_trees = planner.sample(starts, goals, deterministic=True)
    assert mean_trees.shape == (4, 9, 2) and not np.isnan(mean_trees).any()
    straight = starts[:, None] + (goals - starts)[:, None] * np.linspace(0, 1, 9)[None, :, None]
    np.testing.assert_allclose(mean_trees, straight, atol=0.02)  # last layer initialised near zero
    partial = planner.sample(starts, goals, upto_layer=2, rng=np.random.default_rng(0))
    assert np.isnan(partial[:, new_layer_indices(3, 3)]).all()
    assert not np.isnan(partial[:, [0, 2, 4, 6, 8]]).any()
    planner.extend(partial, 3, rng=np.random.default_rng(1))
    assert not np.isnan(partial).any()
    with pytest.raises(ValueError, match="needs layers 0..2"):
        planner.extend(planner.sample(starts, goals, upto_layer=1, rng=0), 3)


def test_samples_are_seeded_and_clipped():
    planner = SubgoalPlanner(2, 2, low=0.0, high=1.0, std=0.5, seed=0)
    starts = np.zeros((50, 2))
    goals = np.zeros((50, 2))
    t1 = planner.sample(starts, goals, rng=np.random.default_rng(3))
    t2 = planner.sample(starts, goals, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(t1, t2)
    assert (t1 >= 0).all() and (t1 <= 1).all() and (t1[:, 1:-1] == 0).any()


def _layer_mean(planner, trees, k):
    """pi_p's mean of layer k's new sub-goals given their parents in `trees`, by hand."""
    li, ri = parent_indices(planner.depth, k)
    with torch.no_grad():
        return planner.mean(
            torch.as_tensor(trees[:, li], dtype=torch.float32),
            torch.as_tensor(trees[:, ri], dtype=torch.float32),
            k,
        ).numpy()


def test_log_prob_equals_hand_computed_gaussian():
    std = np.array([0.05, 0.1])
    planner = SubgoalPlanner(2, 2, low=0.0, high=1.0, std=std, seed=0)
    starts, goals = _tasks(3, seed=1)
    trees = planner.sample(starts, goals, rng=np.random.default_rng(0)).astype(np.float64)
    expected = np.zeros(3)
    per_layer = {}
    for k in (1, 2):
        mu = _layer_mean(planner, trees, k)
        x = trees[:, new_layer_indices(2, k)]
        dens = -0.5 * ((x - mu) / std) ** 2 - np.log(std) - 0.5 * math.log(2 * math.pi)
        per_layer[k] = dens.sum(axis=(1, 2))
        expected += per_layer[k]
    np.testing.assert_allclose(planner.log_prob(trees, [1, 2]).detach().numpy(), expected, rtol=1e-4)
    np.testing.assert_allclose(planner.log_prob(trees, 2).detach().numpy(), expected, rtol=1e-4)
    np.testing.assert_allclose(planner.log_prob(trees, [2]).detach().numpy(), per_layer[2], rtol=1e-4)
    # layer 1 of a fresh planner: mean = midpoint, so the density is a plain Gaussian around it
    mid = (trees[:, 0] + trees[:, 4]) / 2
    fresh = SubgoalPlanner(2, 2, low=0.0, high=1.0, std=std, last_init_scale=0.0)
    z = (trees[:, 2] - mid) / std
    hand = (-0.5 * z**2 - np.log(std) - 0.5 * math.log(2 * math.pi)).sum(1)
    np.testing.assert_allclose(fresh.log_prob(trees, [1]).detach().numpy(), hand, rtol=1e-4)


def test_relative_noise_scales_with_the_parent_segment_and_log_prob_matches_by_hand():
    planner = SubgoalPlanner(2, 2, low=0.0, high=1.0, std=0.1, noise="relative", seed=0)
    starts = np.array([[0.1, 0.5], [0.45, 0.5]])
    goals = np.array([[0.9, 0.5], [0.55, 0.5]])  # parent segments 0.8 and 0.1 long
    rng = np.random.default_rng(0)
    reps = 4000
    trees = planner.sample(np.repeat(starts, reps, 0), np.repeat(goals, reps, 0), upto_layer=1, rng=rng)
    spread = trees[:, 2].reshape(2, reps, 2).std(axis=1).mean(axis=1)
    np.testing.assert_allclose(spread, [0.08, 0.01], rtol=0.08)  # std = 0.1 x parent length
    trees = planner.sample(starts, goals, rng=rng).astype(np.float64)
    expected = np.zeros(2)
    for k in (1, 2):
        li, ri = parent_indices(2, k)
        mu = _layer_mean(planner, trees, k)
        std = np.maximum(0.1 * np.linalg.norm(trees[:, ri] - trees[:, li], axis=-1, keepdims=True), 1e-3)
        x = trees[:, new_layer_indices(2, k)]
        dens = -0.5 * ((x - mu) / std) ** 2 - np.log(std) - 0.5 * math.log(2 * math.pi)
        expected += dens.sum(axis=(1, 2))
    np.testing.assert_allclose(planner.log_prob(trees, 2).detach().numpy(), expected, rtol=1e-4)


def test_set_std_changes_the_spread_and_survives_a_state_dict_round_trip():
    planner = SubgoalPlanner(2, 1, low=0.0, high=1.0, std=0.05, seed=0)
    planner.set_std(0.01)
    starts, goals = np.full((3000, 2), 0.3), np.full((3000, 2), 0.7)
    trees = planner.sample(starts, goals, rng=np.random.default_rng(0))
    assert trees[:, 1].std(axis=0) == pytest.approx([0.01, 0.01], rel=0.08)
    restored = SubgoalPlanner.from_state_dict(planner.state_dict())
    assert restored.std.tolist() == pytest.approx([0.01, 0.01])
    with pytest.raises(ValueError, match="std must be > 0"):
        planner.set_std(0.0)


def test_max_kl_rolls_back_an_update_that_leaves_the_trust_region():
    starts, goals = np.full((8, 2), 0.2), np.full((8, 2), 0.8)
    costs = np.arange(8.0)

    def one_update(max_kl):
        planner = SubgoalPlanner(2, 1, low=0.0, high=1.0, seed=0, max_kl=max_kl)
        trees = planner.sample(starts, goals, rng=np.random.default_rng(0))
        before = [p.detach().clone() for p in planner.parameters()]
        stats = planner.update(trees, costs, upto_layer=1)
        moved = any(not torch.equal(a, b) for a, b in zip(before, planner.parameters(), strict=True))
        return stats, moved, planner

    stats, moved, _ = one_update(None)
    assert moved and stats["rolled_back"] == 0.0
    stats, moved, planner = one_update(1e-12)  # any step leaves a region this small
    assert not moved and stats["rolled_back"] == 1.0
    assert all(not s for s in planner.optimizer.state.values())  # Adam's moments are undone too
    stats, moved, _ = one_update(1e3)
    assert moved and stats["rolled_back"] == 0.0
    with pytest.raises(ValueError, match="max_kl"):
        SubgoalPlanner(2, 1, max_kl=0.0)


def test_group_baseline():
    costs = np.array([1.0, 3.0, 10.0, 20.0, 30.0])
    np.testing.assert_allclose(group_baseline(costs, np.array([0, 0, 1, 1, 1])), [2, 2, 20, 20, 20])
    np.testing.assert_allclose(group_baseline(costs, None), np.full(5, 12.8))


def test_update_lowers_cost_of_simple_objective_and_reports_stats():
    # Cost: distance of the layer-1 midpoint from a target point (0.8, 0.2).
    planner = SubgoalPlanner(2, 1, low=0.0, high=1.0, seed=0)
    starts, goals = np.tile([0.2, 0.5], (8, 1)), np.tile([0.8, 0.5], (8, 1))
    rng = np.random.default_rng(0)
    target = np.array([0.5, 0.3])
    before = np.linalg.norm(planner.sample(starts[:1], goals[:1], deterministic=True)[0, 1] - target)
    for _ in range(60):
        rep_s, rep_g = np.repeat(starts, 8, 0), np.repeat(goals, 8, 0)
        trees = planner.sample(rep_s, rep_g, rng=rng)
        costs = np.linalg.norm(trees[:, 1] - target, axis=-1)
        stats = planner.update(trees, costs, upto_layer=1, group_ids=np.repeat(np.arange(8), 8))
    after = np.linalg.norm(planner.sample(starts[:1], goals[:1], deterministic=True)[0, 1] - target)
    assert set(stats) >= {"loss", "cost_mean", "approx_kl", "clip_fraction"}
    assert 0.0 <= stats["clip_fraction"] <= 1.0 and stats["approx_kl"] >= 0.0
    assert after < 0.5 * before


def test_planner_state_dict_round_trip_includes_optimizer():
    planner = SubgoalPlanner(2, 2, low=0.0, high=1.0, seed=0)
    cost = SegmentCost(alpha=1.0)
    starts, goals = _tasks(4)
    construct_trees(planner, starts, goals, 2, cost, num_samples=4, rng=0)
    state = planner.state_dict()
    assert state["optimizer"]["state"]  # Adam moments exist
    other = SubgoalPlanner.from_state_dict(state)
    third = SubgoalPlanner(2, 2, low=0.0, high=1.0, seed=5)
    third.load_state_dict(state)
    for p in (other, third):
        np.testing.assert_allclose(
            p.sample(starts, goals, deterministic=True), planner.sample(starts, goals, deterministic=True)
        )
    # continuing training gives identical parameters, so the optimizer moments were restored
    construct_trees(planner, starts, goals, 2, cost, num_samples=4, rng=9)
    construct_trees(third, starts, goals, 2, cost, num_samples=4, rng=9)
    np.testing.assert_allclose(
        third.sample(starts, goals, deterministic=True),
        planner.sample(starts, goals, deterministic=True),
        rtol=1e-5,
    )


@pytest.mark.parametrize("shared, augment", [(False, False), (True, True)])
def test_construct_trees_shapes_and_stats(shared, augment):
    planner = SubgoalPlanner(2, 3, low=0.0, high=1.0, shared_across_layers=shared, augment_reversed=augment)
    starts, goals = _tasks(5)
    res = construct_trees(planner, starts, goals, 3, SegmentCost(), num_samples=4, rng=0)
    assert res.trees.shape == (5, 9, 2) and not np.isnan(res.trees).any()
    np.testing.assert_allclose(res.trees[:, 0], starts, rtol=1e-6)
    np.testing.assert_allclose(res.trees[:, -1], goals, rtol=1e-6)
    assert res.layer_costs.shape == (5, 4)
    for k in range(4):
        assert f"cost_layer_{k}" in res.stats
    for k in range(1, 4):
        assert {f"train_cost_J{k}", f"loss_layer_{k}", f"approx_kl_layer_{k}"} <= set(res.stats)
    ev = construct_trees(planner, starts, goals, 3, SegmentCost(), train=False, deterministic=True)
    ev2 = construct_trees(planner, starts, goals, 3, None, train=False, deterministic=True)
    np.testing.assert_array_equal(ev.trees, ev2.trees)
    with pytest.raises(ValueError, match="cost_fn"):
        construct_trees(planner, starts, goals, 3, None)


# ---------------------------------------------------------------- behavioural test: avoid an obstacle
BOX_LO, BOX_HI = np.array([0.4, 0.4]), np.array([0.6, 0.6])


def segment_hits_box(a, b, lo=BOX_LO, hi=BOX_HI):
    """Exact segment-vs-axis-aligned-box test (slab method), batched over rows of a, b [N, 2]."""
    a = np.asarray(a, float)
    d = np.asarray(b, float) - a
    t0, t1 = np.zeros(len(a)), np.ones(len(a))
    ok = np.ones(len(a), bool)
    for i in range(a.shape[1]):
        par = np.abs(d[:, i]) < 1e-12
        ok &= ~(par & ((a[:, i] < lo[i]) | (a[:, i] > hi[i])))
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo[i] - a[:, i]) / d[:, i], (hi[i] - a[:, i]) / d[:, i]
        t0 = np.maximum(t0, np.where(par, -np.inf, np.minimum(ta, tb)))
        t1 = np.minimum(t1, np.where(par, np.inf, np.maximum(ta, tb)))
    return ok & (t0 <= t1)


def test_segment_hits_box_helper():
    a = np.array([[0.1, 0.5], [0.1, 0.1], [0.5, 0.5], [0.1, 0.8], [0.39, 0.0]])
    b = np.array([[0.9, 0.5], [0.9, 0.1], [0.55, 0.55], [0.8, 0.1], [0.39, 1.0]])
    assert segment_hits_box(a, b).tolist() == [True, False, True, True, False]


def _obstacle_run(seed, updates=250, cost=None):
    if cost is None:  # the paper's indicator penalty
        cost = SegmentCost(alpha=1.0, segments_collide=segment_hits_box, collision_penalty=10.0)
    planner = SubgoalPlanner(2, 1, low=0.0, high=1.0, seed=seed)
    B = 8
    starts, goals = np.tile([0.1, 0.5], (B, 1)), np.tile([0.9, 0.5], (B, 1))
    n_eval = 1000
    ev_s, ev_g = np.tile([0.1, 0.5], (n_eval, 1)), np.tile([0.9, 0.5], (n_eval, 1))

    def evaluate():
        trees = planner.sample(ev_s, ev_g, rng=np.random.default_rng(123))
        layer_costs, _ = tree_cost(trees, 1, 1, cost)
        collide = segment_hits_box(*layer_segments(trees, 1, 1)).reshape(n_eval, 2).any(1)
        mean_tree = planner.sample(ev_s[:1], ev_g[:1], deterministic=True)
        mean_collides = bool(segment_hits_box(*layer_segments(mean_tree, 1, 1)).any())
        return {
            "cost": layer_costs[:, 1].mean(),
            "collide": collide.mean(),
            "mid": mean_tree[0, 1],
            "mean_collides": mean_collides,
        }

    before = evaluate()
    rng = np.random.default_rng(seed)
    for _ in range(updates):
        res = construct_trees(planner, starts, goals, 1, cost, num_samples=16, rng=rng)
    return before, evaluate(), res


def test_planner_learns_to_route_around_an_obstacle():
    """Start (0.1, 0.5), goal (0.9, 0.5), square obstacle [0.4, 0.6]^2 in between, K = 1, alpha = 1.

    Honest scope: with the paper's indicator penalty (no gradient inside the obstacle) and std 0.05,
    the symmetric start can break either way. Measured over seeds 0-5 (250 updates each): 4 seeds
    reach a collision-free layer-1 path (expected cost ~1.0-1.9), 2 seeds settle in the local optimum
    "midpoint beside the obstacle, one segment still crosses it" (expected cost ~10.9). So every seed
    must halve the expected cost and move the mean midpoint out of the obstacle; seed 0 must also
    become collision-free.
    """
    for seed in (0, 1, 2):  # seed 2 is one of the runs that stalls with one colliding segment
        before, after, res = _obstacle_run(seed)
        assert before["collide"] > 0.9 and before["mean_collides"] and before["cost"] > 15
        assert after["cost"] < 0.6 * before["cost"], (seed, before["cost"], after["cost"])
        assert not np.all((after["mid"] >= BOX_LO) & (after["mid"] <= BOX_HI)), (seed, after["mid"])
        assert res.stats["cost_layer_1"] < 0.6 * before["cost"]
        if seed == 0:
            # expected cost drops from ~2 penalties (~20) to about the detour length (~1-2)
            assert after["cost"] < 0.2 * before["cost"], after
            assert after["collide"] < 0.25, after  # most stochastic layer-1 paths are collision-free
            assert not after["mean_collides"], after  # the mean layer-1 path is collision-free


def test_length_collision_cost_leads_out_of_the_obstacle_trap():
    """Same problem with SGT-PG's graded cost (100 x length in collision): seeds 2 and 5, which stall
    with one colliding segment under the paper's indicator penalty, find a collision-free layer-1
    path. Measured over seeds 0-5: all six end with a collision-free mean path and <= 8 % colliding
    samples (indicator: seeds 2 and 5 at 100 %)."""
    box = Obstacles(BOX_LO[None], BOX_HI[None])
    for seed in (2, 5):
        before, after, _ = _obstacle_run(
            seed,
            cost=SegmentCost(
                alpha=1.0,
                segments_collide=segment_hits_box,
                collision_penalty=100.0,
                collision_cost="length",
                collision_lengths=box.collision_lengths,
            ),
        )
        assert before["collide"] > 0.9 and before["mean_collides"]
        assert not after["mean_collides"], (seed, after)
        assert after["collide"] < 0.25, (seed, after)


def _one_update(planner, costs_fn, seed=0):
    starts, goals = np.tile([0.2, 0.5], (8, 1)), np.tile([0.8, 0.5], (8, 1))
    rng = np.random.default_rng(seed)
    trees = planner.sample(np.repeat(starts, 8, 0), np.repeat(goals, 8, 0), rng=rng)
    return planner.update(trees, costs_fn(trees), upto_layer=1, group_ids=np.repeat(np.arange(8), 8))


def test_target_kl_stops_the_epochs_early():
    def costs(trees):
        return np.linalg.norm(trees[:, 1] - np.array([0.5, 0.3]), axis=-1)

    assert _one_update(SubgoalPlanner(2, 1, low=0.0, high=1.0, seed=0, epochs=4), costs)["epochs_run"] == 4
    # The first epoch starts at the sampling policy (KL 0); after one step the KL exceeds 1.5e-12.
    stats = _one_update(SubgoalPlanner(2, 1, low=0.0, high=1.0, seed=0, epochs=4, target_kl=1e-12), costs)
    assert stats["epochs_run"] == 1
    with pytest.raises(ValueError, match="target_kl"):
        SubgoalPlanner(2, 1, target_kl=0.0)


def test_non_finite_costs_never_reach_the_weights():
    planner = SubgoalPlanner(2, 1, low=0.0, high=1.0, seed=0)
    before = {k: v.clone() for k, v in planner.nets.state_dict().items()}
    stats = _one_update(planner, lambda trees: np.where(np.arange(len(trees)) == 3, np.nan, 1.0))
    assert stats["nonfinite_skipped"] == 1 and stats["epochs_run"] == 0
    for name, value in planner.nets.state_dict().items():
        torch.testing.assert_close(value, before[name])


def test_planner_at_paper_settings_stays_stable_on_four_rooms():
    """K = 5, lr 0.005, std 0.05, B = 30 x 16 samples, four-rooms, alpha = 1 (the planner phase before any
    time cost). Without a gradient-norm clip this run diverged by planner phase ~100 (approx. KL in the
    millions, test cost 440 -> 654, then NaN weights); with CO-PILOT's default clip of 0.5 the test cost
    fell to ~30 and 81-83 % of test plans were collision-free after 400 phases (seeds 0 and 1). Scored
    here on the validation tasks, as anything that probes the planner is."""
    from copilot_ray.algorithms.copilot.settings import SETTINGS
    from copilot_ray.envs import make

    env = make("maze-point", layout="four-rooms").unwrapped
    planner = SubgoalPlanner(
        2,
        5,
        env.goal_space.low,
        env.goal_space.high,
        seed=0,
        max_grad_norm=SETTINGS["planner.max_grad_norm"].default,
    )
    cost = SegmentCost(alpha=1.0, segments_collide=env.segments_collide, collision_penalty=10.0)
    train, validation = env.tasks("train"), env.tasks("validation")
    rng = np.random.default_rng(0)

    def validation_cost():
        return cost.tree_cost(planner.sample(*validation, deterministic=True))[1].mean()

    before, max_kl = validation_cost(), 0.0
    for _ in range(120):
        idx = rng.choice(len(train[0]), size=30, replace=False)
        res = construct_trees(planner, train[0][idx], train[1][idx], 5, cost, num_samples=16, rng=rng)
        max_kl = max(max_kl, *(res.stats[f"approx_kl_layer_{k}"] for k in range(1, 6)))
        assert res.stats["nonfinite_skipped"] == 0
    after = validation_cost()
    assert all(torch.isfinite(p).all() for p in planner.nets.parameters())
    assert max_kl < 10.0, max_kl
    assert after < 0.5 * before, (before, after)


def test_angle_dims_take_the_short_way_wrap_samples_and_scale_the_std():
    low, high = np.array([0.0, -np.pi]), np.array([1.0, np.pi])
    planner = SubgoalPlanner(
        2, 1, low, high, std=0.1, angle_dims=(1,), std_scale=[1.0, 5.0], last_init_scale=0.0
    )
    starts, goals = np.array([[0.2, 3.0]]), np.array([[0.6, -3.0]])
    mean = planner.sample(starts, goals, deterministic=True)[0, 1]
    # across the seam the midpoint of 3.0 and -3.0 is pi (short way), not 0 (half a turn away)
    assert mean[0] == pytest.approx(0.4) and abs(abs(mean[1]) - np.pi) < 1e-5
    samples = planner.sample(np.repeat(starts, 4000, 0), np.repeat(goals, 4000, 0), rng=0)[:, 1]
    assert (samples[:, 1] >= -np.pi).all() and (samples[:, 1] < np.pi).all()  # wrapped, never clipped
    assert np.std(samples[:, 0]) == pytest.approx(0.1, rel=0.1)
    spread = np.angle(np.exp(1j * (samples[:, 1] - np.pi)))  # offsets from pi, wrapped
    assert np.std(spread) == pytest.approx(0.1 * 5.0, rel=0.1)  # std x std_scale in the angle
    # the density sees the wrapped offset: a sample just across the seam is as likely as its mirror
    near = np.array(
        [[[0.2, 3.0], [0.4, np.pi - 0.05], [0.6, -3.0]], [[0.2, 3.0], [0.4, -np.pi + 0.05], [0.6, -3.0]]]
    )
    logp = planner.log_prob(near, 1).detach().numpy()
    assert logp[0] == pytest.approx(logp[1], abs=1e-4)
    restored = SubgoalPlanner.from_state_dict(planner.state_dict())
    assert restored.angle_dims == (1,) and restored._std_t.tolist() == planner._std_t.tolist()


def test_from_settings_applies_the_angles_setting_to_an_env_geometry():
    from copilot_ray.algorithms.copilot.settings import defaults
    from copilot_ray.envs import make

    geometry = make("maze-rigid", layout="u-maze").unwrapped.agent_geometry
    settings = defaults("planner")
    low, high = geometry.bounds
    by_mode = {
        mode: SubgoalPlanner.from_settings({**settings, "angles": mode}, 3, 2, low, high, geometry=geometry)
        for mode in ("raw", "wrapped", "scaled")
    }
    assert by_mode["raw"].angle_dims == () and by_mode["wrapped"].angle_dims == (2,)
    assert by_mode["wrapped"].std_scale.tolist() == [1, 1, 1]
    assert by_mode["scaled"].std_scale.tolist() == pytest.approx([1.0, 1.0, 1 / 0.025])
    with pytest.raises(ValueError, match="angles must be one of"):
        SubgoalPlanner.from_settings({**settings, "angles": "polar"}, 3, 2, low, high, geometry=geometry)


def _thrown(planner: SubgoalPlanner, offset: float) -> SubgoalPlanner:
    """The planner after an update that threw every layer's output `offset` half-widths off the midpoint."""
    with torch.no_grad():
        for net in planner.nets:
            net[-1].bias.fill_(offset)
    return planner


def test_a_squashed_mean_stays_in_the_box_where_a_free_one_leaves_it():
    starts, goals = _tasks(4, d=3, seed=2)
    low, high = np.array([0.0, 0.0, -np.pi]), np.array([1.0, 1.0, np.pi])
    free = _thrown(SubgoalPlanner(3, 2, low, high, angle_dims=[2], seed=0), 5.0)
    squashed = _thrown(SubgoalPlanner(3, 2, low, high, angle_dims=[2], mean="squashed", seed=0), 5.0)
    trees = free.sample(starts, goals, deterministic=True)
    mu_free, mu_squashed = (_layer_mean(p, trees, 2) for p in (free, squashed))
    assert (mu_free[..., :2] > 1.0).all()  # thrown past the border: every sample is clipped onto it
    assert (mu_squashed[..., :2] < 1.0).all() and (mu_squashed[..., :2] > 0.99).all()
    # the tanh maps the box's inside monotonically: an in-box free mean keeps its order and stays inside
    inside = _layer_mean(SubgoalPlanner(3, 2, low, high, mean="squashed", last_init_scale=0.0), trees, 1)
    assert ((inside[..., :2] > 0) & (inside[..., :2] < 1)).all()
    np.testing.assert_allclose(mu_squashed[..., 2], mu_free[..., 2], rtol=1e-6)  # angles wrap instead
    # the density is the Gaussian around the squashed mean (positions only: angles' differences wrap)
    squashed = _thrown(SubgoalPlanner(2, 2, 0.0, 1.0, mean="squashed", seed=0), 5.0)
    starts, goals = _tasks(4, seed=2)
    sampled = squashed.sample(starts, goals, rng=np.random.default_rng(1)).astype(np.float64)
    x, mu = sampled[:, new_layer_indices(2, 2)], _layer_mean(squashed, sampled, 2)
    std = squashed.std.astype(np.float64)
    hand = (-0.5 * ((x - mu) / std) ** 2 - np.log(std) - 0.5 * math.log(2 * math.pi)).sum(axis=(1, 2))
    np.testing.assert_allclose(squashed.log_prob(sampled, [2]).detach().numpy(), hand, rtol=1e-4)


def test_a_leaky_mean_is_free_inside_the_box_and_leaks_back_from_outside():
    starts, goals = _tasks(4, seed=3)
    free, leaky = (SubgoalPlanner(2, 2, 0.0, 1.0, mean=m, seed=0) for m in ("free", "leaky"))
    trees = free.sample(starts, goals, deterministic=True)
    # inside the box it is the reference code's mean, exactly
    np.testing.assert_array_equal(_layer_mean(leaky, trees, 2), _layer_mean(free, trees, 2))
    thrown_free, thrown = (
        _layer_mean(_thrown(free, 5.0), trees, 2),
        _layer_mean(_thrown(leaky, 5.0), trees, 2),
    )
    np.testing.assert_allclose(thrown, 1.0 + 0.01 * (thrown_free - 1.0), rtol=1e-6)  # the border + 1 %
    # what a thrown free mean loses: its samples all clip onto one border point (equal costs, no
    # advantage to learn from); the leaky one's still differ, so PPO still has a signal to pull it back
    rng = np.random.default_rng(0)
    layer = new_layer_indices(2, 2)
    many = np.repeat(starts, 50, 0), np.repeat(goals, 50, 0)
    free_samples = free.sample(*many, rng=rng)[:, layer]
    leaky_samples = leaky.sample(*many, rng=rng)[:, layer]
    assert (free_samples == 1.0).all()
    assert 0.15 < (leaky_samples < 1.0).mean() < 0.5  # the mean just past the border


def test_the_mean_setting_reaches_the_planner_and_its_checkpoint():
    from copilot_ray.algorithms.copilot.settings import PRESETS, defaults
    from copilot_ray.algorithms.sgt_pg.settings import SETTINGS as SGT_PG_SETTINGS

    settings = defaults("planner")
    assert (
        settings["mean"] == "leaky"
    )  # CO-PILOT's default; the paper's reading and SGT-PG keep the free mean
    assert PRESETS["paper_literal"]["planner"]["mean"] == "free"
    assert SGT_PG_SETTINGS["planner.mean"].default == "free"
    planner = SubgoalPlanner.from_settings({**settings, "mean": "squashed"}, 2, 2, 0.0, 1.0)
    restored = SubgoalPlanner.from_state_dict(_thrown(planner, 5.0).state_dict())
    assert restored.mean_mode == "squashed"
    starts, goals = _tasks(2)
    trees = planner.sample(starts, goals, deterministic=True)
    np.testing.assert_array_equal(_layer_mean(restored, trees, 1), _layer_mean(planner, trees, 1))
    old_checkpoint = planner.state_dict()
    del old_checkpoint["config"]["mean"]  # written before the setting existed
    assert SubgoalPlanner.from_state_dict(old_checkpoint).mean_mode == "free"
    with pytest.raises(
        ValueError, match=r"mean must be one of \('free', 'squashed', 'leaky'\), got mean='tanh'"
    ):
        SubgoalPlanner(2, 2, 0.0, 1.0, mean="tanh")
