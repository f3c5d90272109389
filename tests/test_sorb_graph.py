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
