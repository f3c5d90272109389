"""SoRB's replay graph: edges up to the cutoff, shortest routes through the nodes, straight when close."""

import numpy as np
import pytest

from copilot_ray.algorithms.sorb.graph import ReplayGraph, pad_front


def euclid_steps(step):
    """A 'critic' that knows the true distance, in steps of `step`."""

    def distance(observations, achieved, goals):
        return np.linalg.norm(achieved - goals, axis=1) / step

    return distance


def line_nodes(n=11):
    xs = np.linspace(0.0, 1.0, n)
    pts = np.stack([xs, np.zeros(n)], axis=1).astype(np.float32)
    return pts, pts.copy()


def test_route_hops_along_the_line_within_the_cutoff():
    obs, ach = line_nodes()
    graph = ReplayGraph.build(obs, ach, euclid_steps(0.01), max_edge_steps=15)  # edges up to 0.15
    assert graph.num_edges == 2 * 10  # only neighbours 0.1 apart
    start, goal = np.array([[0.0, 0.02]], np.float32), np.array([[1.0, 0.02]], np.float32)
    (path,) = graph.waypoints(start, start, goal)
    np.testing.assert_allclose(path[0], start[0])
    np.testing.assert_allclose(path[-1], goal[0])
    hops = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert (hops <= 0.15 + 1e-6).all()
    assert len(path) == 11  # start, the nodes at 0.1 .. 0.9 (the end nodes are skipped: one hop), goal
    np.testing.assert_allclose(graph.steps[0, 10], 100.0, rtol=1e-5)


def test_close_goals_and_unconnected_ones_go_straight():
    obs, ach = line_nodes()
    graph = ReplayGraph.build(obs, ach, euclid_steps(0.01), max_edge_steps=15)
    near = graph.waypoints(np.array([[0.3, 0.0]]), np.array([[0.3, 0.0]]), np.array([[0.4, 0.0]]))[0]
    assert len(near) == 2
    far_off = np.array([[0.5, 0.9]], np.float32)  # no node within the cutoff of the goal
    lost = graph.waypoints(np.array([[0.0, 0.0]]), np.array([[0.0, 0.0]]), far_off)[0]
    assert len(lost) == 2


def test_pad_front_repeats_the_start():
    a = np.array([[0.0, 0.0], [1.0, 1.0]])
    b = np.array([[5.0, 5.0], [6.0, 6.0], [7.0, 7.0], [8.0, 8.0]])
    out = pad_front([a, b])
    assert out.shape == (2, 4, 2)
    np.testing.assert_array_equal(out[0], [[0, 0], [0, 0], [0, 0], [1, 1]])
    np.testing.assert_array_equal(out[1], b)


def test_bad_graphs_are_refused():
    obs, ach = line_nodes()
    with pytest.raises(ValueError, match="max_edge_steps"):
        ReplayGraph.build(obs, ach, euclid_steps(0.01), max_edge_steps=0)
    with pytest.raises(ValueError, match="at least one state"):
        ReplayGraph.build(obs[:0], ach[:0], euclid_steps(0.01), max_edge_steps=5)


def wall_at(x, checked):
    """The map of a wall across the plane at x (a segment crossing it is blocked); counts its checks."""

    def segment_free(a, b):
        checked.append(len(a))
        return ~((a[:, 0] - x) * (b[:, 0] - x) < 0)

    return segment_free


def test_with_the_map_no_kept_edge_crosses_a_wall_and_every_check_is_counted():
    """SoRB with the map: the critic keeps edges up to the cutoff (here neighbours 0.1 apart and their
    second neighbours), the map drops those across the wall at x = 0.55, so nothing routes across it;
    the start-to-node, node-to-goal and direct edges are checked too. Without the map the same graph
    routes across the wall."""
    obs, ach = line_nodes()
    start, goal = np.array([[0.0, 0.0]], np.float32), np.array([[1.0, 0.0]], np.float32)
    plain = ReplayGraph.build(obs, ach, euclid_steps(0.01), max_edge_steps=25)
    assert len(plain.waypoints(start, start, goal)[0]) > 2
    checked = []
    mapped = ReplayGraph.build(
        obs, ach, euclid_steps(0.01), max_edge_steps=25, segment_free=wall_at(0.55, checked)
    )
    assert checked == [plain.num_edges]  # every edge the critic kept, asked once
    # Crossing edges: 0.5->0.6 and the second neighbours 0.4->0.6, 0.5->0.7, in both directions.
    assert mapped.num_edges == plain.num_edges - 2 * 3
    assert np.isinf(mapped.steps[0, 10]) and np.isfinite(plain.steps[0, 10])
    (path,) = mapped.waypoints(start, start, goal)
    assert len(path) == 2  # no route: straight, as SoRB goes when its graph cannot connect
    # A goal on the start's side is routed, each of its hops free of the wall.
    near_goal = np.array([[0.5, 0.0]], np.float32)
    (route,) = mapped.waypoints(start, start, near_goal)
    assert len(route) > 2 and (route[:, 0] < 0.55).all()
    assert sum(checked) > plain.num_edges  # the route's entry, exit and direct edges were asked too
