"""Exact segment collision, rectangle merging and shortest paths against hand-checked cases."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from copilot_ray.envs.maze import Obstacles, VisibilityGraph, load_layout, merge_cells, parse_layout

E = 2.0**-10  # a dyadic nudge: coordinates stay exact in binary floating point

# 4 x 4 cells of 0.25; the box is cell (row 1, col 1): x in [0.25, 0.5], y in [0.5, 0.75].
BOX = Obstacles.from_layout(parse_layout("....\n.#..\n....\n....\n"))
# A wall at y in [0.5, 0.75] with a one-cell gap at x in [0.5, 0.75].
GAP = Obstacles.from_layout(parse_layout("....\n##.#\n....\n....\n"))


def collides(obstacles, a, b):
    return bool(obstacles.segments_collide(np.array([a]), np.array([b]))[0])


@pytest.mark.parametrize(
    ("a", "b", "expected", "why"),
    [
        ((0.125, 0.625), (0.375, 0.875), True, "line through the corner point (0.25, 0.75) only"),
        ((0.125, 0.625 + E), (0.375, 0.875 + E), False, "grazes the corner from outside"),
        ((0.125, 0.75), (0.625, 0.75), True, "runs along the top edge"),
        ((0.125, 0.75 + E), (0.625, 0.75 + E), False, "runs just above the top edge"),
        ((0.125, 0.6), (0.25, 0.6), True, "ends exactly on the left edge"),
        ((0.125, 0.6), (0.25 - E, 0.6), False, "ends just short of the left edge"),
        ((0.125, 0.6), (0.875, 0.6), True, "crosses the box"),
        ((0.375, 0.625), (0.375, 0.625), True, "a point inside"),
        ((0.25, 0.5), (0.25, 0.5), True, "a point on the corner"),
        ((0.125, 0.125), (0.125, 0.125), False, "a free point"),
        ((0.875, 0.875), (1.125, 0.875), True, "leaves the square"),
        ((0.875, 0.875), (1.0, 0.875), True, "touches the square's border"),
        ((0.875, 0.875), (1.0 - E, 0.875), False, "stops just inside the border"),
        ((0.625, 0.875), (0.875, 0.125), False, "free diagonal"),
    ],
)
def test_single_box_cases(a, b, expected, why):
    assert collides(BOX, a, b) is expected, why
    assert collides(BOX, b, a) is expected, why + " (reversed)"


@pytest.mark.parametrize(
    ("a", "b", "expected", "why"),
    [
        ((0.625, 0.875), (0.625, 0.375), False, "straight through the middle of the gap"),
        ((0.5625, 0.875), (0.6875, 0.375), False, "diagonally through the gap"),
        ((0.5, 0.875), (0.5, 0.375), True, "along the gap's left edge"),
        ((0.75 - E, 0.875), (0.75 - E, 0.375), False, "hugging the gap's right edge"),
        ((0.375, 0.875), (0.875, 0.375), True, "touches the gap's top-left corner (0.5, 0.75)"),
        ((0.125, 0.875), (0.125, 0.375), True, "through the wall"),
    ],
)
def test_one_cell_gap(a, b, expected, why):
    assert collides(GAP, a, b) is expected, why


def test_batched_shapes_and_empty():
    assert BOX.segments_collide(np.zeros((0, 2)), np.zeros((0, 2))).shape == (0,)
    rng = np.random.default_rng(0)
    a, b = rng.random((10_000, 2)), rng.random((10_000, 2))  # more than one chunk
    out = BOX.segments_collide(a, b)
    assert out.shape == (10_000,) and out.dtype == bool
    with pytest.raises(ValueError):
        BOX.segments_collide(np.zeros((3, 2)), np.zeros((2, 2)))


def _liang_barsky(a, b, lo, hi):
    """Reference: closed segment vs closed box by clipping the parameter interval, one pair at a time."""
    t0, t1 = 0.0, 1.0
    for k in range(2):
        d = b[k] - a[k]
        if d == 0.0:
            if not lo[k] <= a[k] <= hi[k]:
                return False
            continue
        ta, tb = (lo[k] - a[k]) / d, (hi[k] - a[k]) / d
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    return t0 <= t1


def test_matches_liang_barsky_on_random_segments():
    obstacles = Obstacles.from_layout(load_layout("random15-3"))
    rng = np.random.default_rng(1)
    a, b = rng.uniform(0.01, 0.99, (2000, 2)), rng.uniform(0.01, 0.99, (2000, 2))
    b[:500] = a[:500] + rng.normal(scale=0.03, size=(500, 2)).clip(-0.009, 0.009)  # short ones too
    expected = [
        any(_liang_barsky(p, q, lo, hi) for lo, hi in zip(obstacles.lo, obstacles.hi, strict=True))
        for p, q in zip(a, b, strict=True)
    ]
    np.testing.assert_array_equal(obstacles.segments_collide(a, b), expected)


def test_collision_lengths_hand_cases():
    box = Obstacles(np.array([[0.4, 0.4]]), np.array([[0.6, 0.6]]))
    a = np.array(
        [[0.1, 0.5], [0.1, 0.1], [0.5, 0.5], [0.5, 0.5], [0.3, 0.3], [0.5, 0.9], [0.4, 0.3], [0, 0.2]]
    )
    b = np.array(
        [[0.9, 0.5], [0.9, 0.1], [0.55, 0.55], [1.5, 0.5], [0.7, 0.7], [0.5, 1.2], [0.3, 0.4], [0, 0.6]]
    )
    # through; beside; inside; through and out of the square (0.1 + 0.5); diagonal; out of the square;
    # touching a corner only; along the border (a wall)
    expected = [0.2, 0.0, 0.05 * np.sqrt(2), 0.6, 0.2 * np.sqrt(2), 0.2, 0.0, 0.4]
    np.testing.assert_allclose(box.collision_lengths(a, b), expected, atol=1e-12)


def test_collision_lengths_match_dense_sampling():
    obstacles = Obstacles.from_layout(load_layout("random15-3"))
    rng = np.random.default_rng(2)
    a, b = rng.uniform(-0.1, 1.1, (5000, 2)), rng.uniform(0.01, 0.99, (5000, 2))  # > one chunk
    got = obstacles.collision_lengths(a, b)
    n = 400  # the dense reference is [n, 4001, boxes] booleans
    t = np.linspace(0.0, 1.0, 4001)[None, :, None]
    points = a[:n, None] + t * (b[:n] - a[:n])[:, None]
    out = ((points <= 0.0) | (points >= 1.0)).any(axis=2)
    inside = ((points[..., None, :] >= obstacles.lo) & (points[..., None, :] <= obstacles.hi)).all(-1).any(-1)
    length = np.linalg.norm(b[:n] - a[:n], axis=1)
    np.testing.assert_allclose(got[:n], length * (out | inside).mean(axis=1), atol=2e-3)
    # Positive length in collision is a collision; free segments have none.
    assert obstacles.segments_collide(a, b)[got > 1e-9].all()
    assert (got[~obstacles.segments_collide(a, b)] == 0.0).all()


def test_merge_cells_covers_exactly_once():
    grid = load_layout("random15-5").grid
    cover = np.zeros(grid.shape, dtype=int)
    rects = merge_cells(grid)
    for r0, c0, r1, c1 in rects:
        cover[r0:r1, c0:c1] += 1
    np.testing.assert_array_equal(cover, grid.astype(int))
    assert len(rects) < grid.sum() / 2  # merging actually merges


def test_clearance():
    c = BOX.clearance(np.array([[0.375, 0.625], [0.125, 0.625], [0.125, 0.875], [0.75, 0.25]]))
    np.testing.assert_allclose(c, [0.0, 0.125, 0.125, 0.25])


def test_shortest_paths_hand_checked():
    empty = Obstacles.from_layout(load_layout("empty"))
    s, g = np.array([[0.1, 0.1], [0.2, 0.9]]), np.array([[0.9, 0.9], [0.2, 0.1]])
    np.testing.assert_allclose(empty.visibility_graph.lengths(s, g), [np.hypot(0.8, 0.8), 0.8])
    # u-maze: wall box x in [0, 0.75], y in [0.375, 0.625]; go round its end at x = 0.75.
    umaze = Obstacles.from_layout(load_layout("u-maze"))
    length = umaze.visibility_graph.lengths(np.array([[0.25, 0.75]]), np.array([[0.25, 0.25]]))[0]
    expected = 2 * np.hypot(0.5, 0.125) + 0.25
    assert length == pytest.approx(expected, abs=1e-5)
    # Unreachable: a goal inside an obstacle.
    assert np.isinf(umaze.visibility_graph.lengths(np.array([[0.1, 0.9]]), np.array([[0.1, 0.5]]))[0])


def test_shortest_path_sealed_room_is_unreachable():
    sealed = Obstacles.from_layout(parse_layout("....\n###.\n..#.\n..#.\n"))
    graph = VisibilityGraph(sealed)
    lengths = graph.lengths(np.array([[0.125, 0.125], [0.125, 0.875]]), np.array([[0.875, 0.125]] * 2))
    assert np.isinf(lengths[0]) and np.isfinite(lengths[1])


FOUR_ROOMS = Obstacles.from_layout(load_layout("four-rooms"))


@settings(max_examples=60, deadline=None)
@given(
    start=st.tuples(st.floats(0.02, 0.98), st.floats(0.02, 0.98)),
    steps=st.lists(st.tuples(st.floats(-0.08, 0.08), st.floats(-0.08, 0.08)), min_size=1, max_size=40),
)
def test_free_steps_never_pass_through_obstacles(start, steps):
    pos = np.array(start)
    if FOUR_ROOMS.clearance(pos[None])[0] <= 0.0:
        return
    t = np.linspace(0.0, 1.0, 65)[:, None]
    for step in steps:
        nxt = pos + np.array(step)
        if FOUR_ROOMS.segments_collide(pos[None], nxt[None])[0]:
            continue  # blocked: stay
        between = pos + t * (nxt - pos)
        assert (FOUR_ROOMS.clearance(between) > 0.0).all(), (pos, nxt)
        pos = nxt
