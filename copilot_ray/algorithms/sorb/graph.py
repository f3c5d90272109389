"""Search on the Replay Buffer (Eysenbach et al., 2019): a graph over replayed states whose edge weights
are the goal-conditioned agent's own distance estimates, searched for waypoints between a start and a
goal. Numpy and SciPy only: the distance function is passed in (SoRB's algorithm derives it from its
critic).

    graph = ReplayGraph.build(observations, achieved, distance, max_edge_steps=50)
    waypoints = graph.waypoints(start_obs, start_achieved, goals)   # one [P_i, d] array per task

Shortest paths between every pair of nodes come from SciPy's `csgraph.shortest_path` (Dijkstra) once per
graph; a task's best route is then min over entry node i and exit node j of
d(s, i) + D[i, j] + d(j, g), with every edge (the first and last included) at most `max_edge_steps`.
A task whose goal is within reach of its start, or that the graph cannot connect, goes straight.

With `segment_free` (SoRB with the map: a batched ground-truth check of the straight segment between two
goal-space points), every edge the distances would keep (node to node, start to node, node to goal, start
to goal) is also checked against the map and dropped when it crosses a wall; the caller counts the checks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

# (observations [n, o], achieved goals of those observations [n, g], goals [n, g]) -> steps [n]
Distance = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
# (a [n, g], b [n, g]) -> bool [n]: the straight segment a -> b touches no wall (the map's answer)
SegmentFree = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class ReplayGraph:
    """Nodes: replayed states (their observations and achieved goals); `steps[i, j]`: shortest-path
    distance in estimated agent steps over edges of at most `max_edge_steps` (inf: unreachable);
    `predecessors`: SciPy's, for the routes."""

    observations: np.ndarray
    achieved: np.ndarray
    steps: np.ndarray
    predecessors: np.ndarray
    max_edge_steps: float
    distance: Distance
    num_edges: int
    segment_free: SegmentFree | None = None

    @classmethod
    def build(
        cls,
        observations: np.ndarray,
        achieved: np.ndarray,
        distance: Distance,
        max_edge_steps: float,
        segment_free: SegmentFree | None = None,
    ) -> ReplayGraph:
        n = len(observations)
        if n == 0:
            raise ValueError("a replay graph needs at least one state")
        if max_edge_steps <= 0:
            raise ValueError(f"max_edge_steps must be > 0, got {max_edge_steps}")
        src, dst = np.divmod(np.arange(n * n), n)
        pairwise = distance(observations[src], achieved[src], achieved[dst]).reshape(n, n)
        keep = (pairwise <= max_edge_steps) & ~np.eye(n, dtype=bool)
        rows, cols = np.nonzero(keep)
        if segment_free is not None:
            free = np.asarray(segment_free(achieved[rows], achieved[cols]), bool)
            rows, cols = rows[free], cols[free]
        # Distances are >= 1 step, so no kept edge has weight 0 (which a sparse matrix would drop).
        weights = np.maximum(pairwise[rows, cols], 1e-6)
        adjacency = csr_matrix((weights, (rows, cols)), shape=(n, n))
        steps, predecessors = shortest_path(adjacency, method="D", directed=True, return_predecessors=True)
        return cls(
            observations,
            achieved,
            steps,
            predecessors,
            float(max_edge_steps),
            distance,
            len(rows),
            segment_free,
        )

    def __len__(self) -> int:
        return len(self.observations)

    def _route(self, i: int, j: int) -> list[int]:
        """Nodes from i to j along the shortest path."""
        route = [j]
        while route[-1] != i:
            route.append(int(self.predecessors[i, route[-1]]))
        return route[::-1]

    def waypoints(
        self, start_observations: np.ndarray, start_achieved: np.ndarray, goals: np.ndarray
    ) -> list[np.ndarray]:
        """Per task, the waypoints [s0, node, ..., node, g] in goal space (just [s0, g] when the goal is
        within one edge of the start, or no route exists)."""
        n, m = len(self), len(goals)
        nodes = np.arange(n)
        # d(start -> node) and d(node -> goal) for every task and node, in one batch each.
        to_node = self.distance(
            np.repeat(start_observations, n, axis=0),
            np.repeat(start_achieved, n, axis=0),
            np.tile(self.achieved, (m, 1)),
        ).reshape(m, n)
        from_node = self.distance(
            np.tile(self.observations, (m, 1)),
            np.tile(self.achieved, (m, 1)),
            np.repeat(goals, n, axis=0),
        ).reshape(m, n)
        direct = self.distance(start_observations, start_achieved, goals)
        limit = self.max_edge_steps
        to_node = np.where(to_node <= limit, to_node, np.inf)
        from_node = np.where(from_node <= limit, from_node, np.inf)
        direct = np.where(direct <= limit, direct, np.inf)
        if self.segment_free is not None:
            to_node = self._walled_off(to_node, start_achieved, self.achieved)
            from_node = self._walled_off(from_node, self.achieved, goals, node_first=True)
            reach = np.flatnonzero(np.isfinite(direct))
            if len(reach):
                blocked = ~np.asarray(self.segment_free(start_achieved[reach], goals[reach]), bool)
                direct[reach[blocked]] = np.inf
        out = []
        for t in range(m):
            first, last = to_node[t], from_node[t]
            via = first[:, None] + self.steps  # [entry i, exit j]
            entry = np.argmin(via, axis=0)  # best entry for every exit
            total = via[entry, nodes] + last
            exit_node = int(np.argmin(total))
            straight = np.isfinite(direct[t]) and direct[t] <= total[exit_node]
            if straight or not np.isfinite(total[exit_node]):
                out.append(np.stack([start_achieved[t], goals[t]]))
                continue
            route = self._route(int(entry[exit_node]), exit_node)
            out.append(np.concatenate([start_achieved[t][None], self.achieved[route], goals[t][None]]))
        return out

    def _walled_off(
        self, steps: np.ndarray, a: np.ndarray, b: np.ndarray, node_first: bool = False
    ) -> np.ndarray:
        """`steps` [tasks, nodes] with inf where the kept edge's straight segment crosses a wall: task
        point a[t] -> node b[i], or (node_first) node a[i] -> task point b[t]."""
        tasks, nodes = np.nonzero(np.isfinite(steps))
        if len(tasks) == 0:
            return steps
        start, end = (a[nodes], b[tasks]) if node_first else (a[tasks], b[nodes])
        blocked = ~np.asarray(self.segment_free(start, end), bool)
        out = steps.copy()
        out[tasks[blocked], nodes[blocked]] = np.inf
        return out


def pad_front(paths: list[np.ndarray]) -> np.ndarray:
    """Paths of different lengths as one [N, P, d] array, each padded at the front with copies of its
    start (a waypoint at the agent's own position is reached in one step, so padding costs no budget
    beyond those steps and gives no extra attempts)."""
    longest = max(len(p) for p in paths)
    return np.stack([np.concatenate([np.repeat(p[:1], longest - len(p), axis=0), p]) for p in paths])
