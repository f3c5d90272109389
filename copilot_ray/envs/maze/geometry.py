"""Obstacle geometry of a maze: merged rectangles, exact batched segment collision, shortest paths.

Everything lives in a rectangular region (the unit square [0, 1]^2 for the 1 x 1 mazes; the Ant maze
passes its own, in metres) whose border is a wall. Obstacles are closed boxes, so a segment that merely
touches a box (a corner, an edge) collides; so does one that touches the border.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy.sparse.csgraph import shortest_path

from .layouts import Layout

# Segments per chunk: bounds the [chunk, boxes] temporaries to a few MB whatever N is.
_CHUNK = 4096


def merge_cells(grid: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Cover the obstacle cells with few non-overlapping rectangles (row0, col0, row1, col1), exclusive ends.

    Greedy: extend right as far as possible, then down while the whole run is obstacle. Fewer boxes make
    every collision query proportionally cheaper.
    """
    rows, cols = grid.shape
    covered = np.zeros_like(grid, dtype=bool)
    rects = []
    for r in range(rows):
        for c in range(cols):
            if not grid[r, c] or covered[r, c]:
                continue
            c1 = c
            while c1 < cols and grid[r, c1] and not covered[r, c1]:
                c1 += 1
            r1 = r + 1
            while r1 < rows and grid[r1, c:c1].all() and not covered[r1, c:c1].any():
                r1 += 1
            covered[r:r1, c:c1] = True
            rects.append((r, c, r1, c1))
    return rects


def _clipped_fraction(
    a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, open_box: bool = False
) -> np.ndarray:
    """[N, boxes]: the fraction of segment a -> b (t in [0, 1]) that lies inside each box (Liang-Barsky).

    Boxes are closed; `open_box` makes them open, which only matters for a segment running exactly
    along a face (the other boundary contacts have length 0)."""
    d = (b - a)[:, None, :]  # [N, 1, 2]
    a = a[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo[None] - a) / d, (hi[None] - a) / d  # [N, boxes, 2]
    parallel = d == 0.0
    # Parallel to an axis: inside that slab for every t, or for none.
    in_slab = ((a > lo[None]) & (a < hi[None])) if open_box else ((a >= lo[None]) & (a <= hi[None]))
    t_enter = np.where(parallel, np.where(in_slab, -np.inf, np.inf), np.minimum(ta, tb)).max(axis=2)
    t_exit = np.where(parallel, np.where(in_slab, np.inf, -np.inf), np.maximum(ta, tb)).min(axis=2)
    return np.clip(np.minimum(t_exit, 1.0) - np.maximum(t_enter, 0.0), 0.0, None)


class Obstacles:
    """The obstacles of one layout as axis-aligned boxes `lo[i] <= p <= hi[i]` (float64), inside the
    region `region_lo < p < region_hi` (default the unit square)."""

    def __init__(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        region: tuple[np.ndarray, np.ndarray] = (np.zeros(2), np.ones(2)),
    ):
        self.lo = np.asarray(lo, dtype=np.float64).reshape(-1, 2)
        self.hi = np.asarray(hi, dtype=np.float64).reshape(-1, 2)
        self.region_lo, self.region_hi = (np.asarray(r, dtype=np.float64).reshape(2) for r in region)
        if not (self.region_lo < self.region_hi).all():
            raise ValueError(f"empty region: low {self.region_lo.tolist()}, high {self.region_hi.tolist()}")

    @classmethod
    def from_layout(cls, layout: Layout) -> Obstacles:
        rows, cols = layout.grid.shape
        boxes = merge_cells(layout.grid)
        # Divide integers (not multiply a cell size) so shared edges get bit-identical coordinates.
        lo = [(c0 / cols, (rows - r1) / rows) for r0, c0, r1, c1 in boxes]
        hi = [(c1 / cols, (rows - r0) / rows) for r0, c0, r1, c1 in boxes]
        return cls(np.array(lo).reshape(-1, 2), np.array(hi).reshape(-1, 2))

    def __len__(self) -> int:
        return len(self.lo)

    def segments_collide(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """bool [N]: does the closed segment a[i] -> b[i] touch an obstacle or the square's border?

        Exact (up to float rounding) by the separating-axis test for a segment against a box: they meet
        iff their bounding boxes overlap (the box's two axes) and the box's corners are not all strictly
        on one side of the segment's line (the segment's normal). The line test is separable in x and y,
        so min/max over the four corners cost four products. A zero-length segment is a point test.
        """
        a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
        if a.shape != b.shape:
            raise ValueError(f"segment endpoints differ in shape: {a.shape} vs {b.shape}")
        # The region is convex: a segment stays strictly inside iff both endpoints do.
        rlo, rhi = self.region_lo, self.region_hi
        out = ((a <= rlo) | (a >= rhi) | (b <= rlo) | (b >= rhi)).any(axis=1)
        if len(self.lo) == 0:
            return out
        x0, y0 = self.lo[:, 0], self.lo[:, 1]
        x1, y1 = self.hi[:, 0], self.hi[:, 1]
        for s in range(0, len(a), _CHUNK):
            ax, ay = a[s : s + _CHUNK, 0:1], a[s : s + _CHUNK, 1:2]
            bx, by = b[s : s + _CHUNK, 0:1], b[s : s + _CHUNK, 1:2]
            hit = (np.maximum(ax, bx) >= x0) & (np.minimum(ax, bx) <= x1)
            hit &= (np.maximum(ay, by) >= y0) & (np.minimum(ay, by) <= y1)
            dx, dy = bx - ax, by - ay
            # f(corner) = dx * (cy - ay) - dy * (cx - ax): the corner's side of the segment's line.
            p0, p1 = dx * (y0 - ay), dx * (y1 - ay)
            q0, q1 = dy * (x0 - ax), dy * (x1 - ax)
            hit &= np.minimum(p0, p1) - np.maximum(q0, q1) <= 0.0
            hit &= np.maximum(p0, p1) - np.minimum(q0, q1) >= 0.0
            out[s : s + _CHUNK] |= hit.any(axis=1)
        return out

    def collision_lengths(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """float [N]: length of the segment a[i] -> b[i] inside obstacles or outside the region.

        A graded version of `segments_collide` for planning costs (SGT-PG's reference planner charges
        length in collision): a sub-goal deep inside a wall costs more than one at its edge, so the
        planner can tell which way is out. Per box, the Liang-Barsky clip gives the parameter interval
        inside it; the merged boxes do not overlap, so the lengths add (a segment running exactly along
        an edge two boxes share is counted twice, a measure-zero case). Running along the border counts
        as outside it. Touching a box or the border at a point is length 0 (`segments_collide` is True).
        """
        a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
        b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
        if a.shape != b.shape:
            raise ValueError(f"segment endpoints differ in shape: {a.shape} vs {b.shape}")
        length = np.linalg.norm(b - a, axis=1)
        region = (self.region_lo[None], self.region_hi[None])
        # The border is a wall: free space is the open region, so a run along the border is in collision.
        outside = length * (1.0 - _clipped_fraction(a, b, *region, open_box=True).sum(axis=1))
        inside = np.zeros(len(a))
        if len(self.lo):
            for s in range(0, len(a), _CHUNK):
                part = _clipped_fraction(a[s : s + _CHUNK], b[s : s + _CHUNK], self.lo, self.hi)
                inside[s : s + _CHUNK] = length[s : s + _CHUNK] * part.sum(axis=1)
        return np.maximum(outside, 0.0) + inside

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """float [N]: Euclidean distance from each point to the nearest obstacle or the border (0 inside)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        border = np.minimum(p - self.region_lo, self.region_hi - p).min(axis=1).clip(min=0.0)
        if len(self.lo) == 0:
            return border
        return np.minimum(border, self.box_distances(p).min(axis=1))

    def box_distances(self, points: np.ndarray) -> np.ndarray:
        """float [N, boxes]: Euclidean distance from each point to each obstacle box (0 inside)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        gap = np.maximum(np.maximum(self.lo[None] - p[:, None], p[:, None] - self.hi[None]), 0.0)
        return np.sqrt((gap**2).sum(axis=2))

    @cached_property
    def visibility_graph(self) -> VisibilityGraph:
        return VisibilityGraph(self)


class VisibilityGraph:
    """Exact shortest collision-free paths for a point among the boxes.

    A shortest path in a polygonal domain bends only at convex obstacle corners. Touching is a collision,
    so nodes sit `offset` diagonally outside each box corner; corners that are not convex corners of the
    obstacle union land inside (or on) another box and are dropped. Lengths are exact up to O(offset).
    """

    def __init__(self, obstacles: Obstacles, offset: float = 1e-7):
        self.obstacles = obstacles
        corners = []
        for sx in (-1.0, 1.0):
            for sy in (-1.0, 1.0):
                cx = np.where(sx < 0, obstacles.lo[:, 0], obstacles.hi[:, 0]) + sx * offset
                cy = np.where(sy < 0, obstacles.lo[:, 1], obstacles.hi[:, 1]) + sy * offset
                corners.append(np.stack([cx, cy], axis=1))
        nodes = np.concatenate(corners) if corners else np.zeros((0, 2))
        nodes = nodes[~obstacles.segments_collide(nodes, nodes)]
        self.nodes = np.unique(nodes, axis=0)
        n = len(self.nodes)
        i, j = np.triu_indices(n, k=1)
        weights = np.zeros((n, n))
        free = ~obstacles.segments_collide(self.nodes[i], self.nodes[j])
        weights[i[free], j[free]] = np.linalg.norm(self.nodes[i[free]] - self.nodes[j[free]], axis=1)
        # Dense zeros mean "no edge" to csgraph; all node distances are > 0 since nodes are unique.
        self.node_distances = shortest_path(weights, method="D", directed=False) if n else np.zeros((0, 0))

    def _to_nodes(self, points: np.ndarray) -> np.ndarray:
        """[Q, n]: straight-line distance from each point to each node, inf where the segment collides."""
        q, n = len(points), len(self.nodes)
        a = np.repeat(points, n, axis=0)
        b = np.tile(self.nodes, (q, 1))
        d = np.linalg.norm(a - b, axis=1)
        d[self.obstacles.segments_collide(a, b)] = np.inf
        return d.reshape(q, n)

    def lengths(self, starts: np.ndarray, goals: np.ndarray, chunk: int = 64) -> np.ndarray:
        """float [Q]: shortest collision-free path length start[i] -> goal[i]; inf if none exists."""
        starts = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
        goals = np.asarray(goals, dtype=np.float64).reshape(-1, 2)
        direct = np.linalg.norm(goals - starts, axis=1)
        direct[self.obstacles.segments_collide(starts, goals)] = np.inf
        if len(self.nodes) == 0:
            return direct
        out = direct.copy()
        for s in range(0, len(starts), chunk):
            from_start = self._to_nodes(starts[s : s + chunk])
            to_goal = self._to_nodes(goals[s : s + chunk])
            # min over (i, j) of start->i + D[i, j] + j->goal, without a [Q, n, n] for all Q at once.
            via = (from_start[:, :, None] + self.node_distances[None]).min(axis=1)
            out[s : s + chunk] = np.minimum(out[s : s + chunk], (via + to_goal).min(axis=1))
        # A point whose own position collides has no path at all.
        bad = self.obstacles.segments_collide(starts, starts) | self.obstacles.segments_collide(goals, goals)
        out[bad] = np.inf
        return out
