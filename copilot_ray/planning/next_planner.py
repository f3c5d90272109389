"""NEXT: a sampling-based tree search guided by a learned policy and value (Chen, Dai, Lin, Ye, Liu, Song,
"Learning to Plan in High Dimensions via Neural Exploration-Exploitation Trees", ICLR 2020).

A baseline planner next to RRT* (``rrt_star``) and SGT-PG, scored the same way (``path_metrics``).

**Search** (``next_search``), RRT*-like, one query at a time. Each iteration either

* extends towards the goal (``goal_bias`` of the iterations) or a uniform sample (``uniform_share``) from
  the nearest tree node, as RRT does (this share keeps the search probabilistically complete whatever the
  model says; with no model every iteration is of this kind: the uniform baseline, the paper code's
  ``RRTS_plan``), or
* selects a node by a UCB score and expands it with the policy: ``Q(node) + c * sqrt(log W / w(node))``
  where ``Q = -V(node, goal) / D`` (the value's predicted cost-to-go in units of the space's diameter D),
  ``w`` is a kernel-smoothed visit count (``sum_a exp(-(d(node, a) / step)^2)`` over every state the
  search tried to reach, collided ones too, as the paper's KDE-UCB) and ``W`` its sum over the tree;
  ``candidates`` samples of the policy's Gaussian at the node are scored the same way and the best one
  is extended to.

Every extension is steered to at most ``step`` (the env's distance, angles the short way round) and its
motion checked with the env's own batched check (counted); a free new state gets the cheapest collision-
free parent within ``rewire_factor * step`` (lazy: cheapest first) and then rewires its neighbours through
itself when that is shorter (RRT*). A new state within ``step`` of the goal also tries the straight motion
to the goal itself. The search stops when a state within the success radius is reached (after
``improve_iterations`` more iterations, which rewiring uses to shorten the path), or at ``max_checks``
collision checks or ``max_iterations``. Randomness is a ``numpy.random.Generator``: deterministic under a
seed.

**Model** (``NEXTModel``): two MLPs on features of (state, goal): each non-angle dim scaled to [-1, 1],
each angle as (sin, cos), and the weighted, wrapped difference goal - state. The *policy* is a Gaussian
over the displacement to the next state, in units of ``step`` per distance-weighted dim (so one scale for
positions and angles), with a fixed std ``policy_std`` as in the paper's code; the *value* regresses the
remaining path length (in units of D). Chosen instead of the paper's attention-based value-iteration
module because the planner here is trained per layout (as CO-PILOT and SGT-PG are): the map never
changes, so an MLP on (state, goal) can learn it, and the paper's module exists to generalise across
maps; an MLP is also fast enough on two CPU cores.

**Training** (``NEXTPlanner``), by imitation of solved paths: each path is cut into pieces of at most
``step`` (the motions the search makes), and every waypoint gives a policy target (the next waypoint:
maximum likelihood of the fixed-std Gaussian = squared error) and a value target (the remaining length to
the goal). With ``hindsight`` every later waypoint also serves as a goal (a sub-path of a short path is
short), which multiplies the data a few demonstrations give. Demonstrations first (RRT* on training
tasks: ``rrt_star_demonstrations``, or this search with uniform sampling), then self-improvement: the
guided search on training tasks, its solved paths added to the data, and more training.

Departures from the paper: an MLP instead of the attention/value-iteration network (above); states that
collide are not inserted into the tree (their attempts still count as visits, which is what the paper's
tree used them for); the value is a regression on remaining length (the paper's code learns a value from
its trees with its own costs); the uniform share is a constant rather than annealed; the goal connection
within one step is added (RRT* planners commonly do this; it saves the wait for a goal-biased sample).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

__all__ = [
    "ConfigSpace",
    "NEXTModel",
    "NEXTPlanner",
    "SearchResult",
    "SearchSettings",
    "TrainSettings",
    "next_search",
    "padded_paths",
    "rrt_star_demonstrations",
]


# ------------------------------------------------------------------------------------------ the space
class ConfigSpace:
    """A configuration space: box bounds, wrapped angle dims, the env's distance and its weights.

    ``distance(a, b)`` is the env's (``goal_distance``: broadcasting [..., d] arrays); ``weights`` are
    the geometry's ``distance_weights`` (distance = sqrt(sum_i (w_i delta_i)^2), angles wrapped).
    """

    def __init__(
        self,
        low: Sequence[float],
        high: Sequence[float],
        distance: Callable[[np.ndarray, np.ndarray], np.ndarray],
        angle_dims: Sequence[int] = (),
        weights: Sequence[float] | None = None,
    ):
        self.low = np.asarray(low, np.float64).copy()
        self.high = np.asarray(high, np.float64).copy()
        if self.low.shape != self.high.shape or self.low.ndim != 1 or not (self.high > self.low).all():
            raise ValueError(f"bounds need low < high per dim, got low={self.low}, high={self.high}")
        self.dim = len(self.low)
        self.distance = distance
        self.angle = np.zeros(self.dim, bool)
        self.angle[list(angle_dims)] = True
        self.weights = np.ones(self.dim) if weights is None else np.asarray(weights, np.float64).copy()
        if self.weights.shape != (self.dim,) or not (self.weights > 0).all():
            raise ValueError(f"weights must be {self.dim} positive numbers, got {weights!r}")
        extent = np.where(self.angle, np.pi, self.high - self.low)  # the largest (wrapped) difference
        self.diameter = float(np.sqrt(((self.weights * extent) ** 2).sum()))
        self.feature_dim = 2 * (self.dim + int(self.angle.sum())) + self.dim

    @classmethod
    def from_env(cls, env) -> ConfigSpace:
        """The space of a maze env (bounds, angles and weights from its agent geometry)."""
        maze = env.unwrapped
        geometry = maze.agent_geometry
        low, high = geometry.bounds
        return cls(low, high, maze.goal_distance, geometry.angle_dims, geometry.distance_weights)

    def dist(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.asarray(self.distance(a, b), np.float64)

    def delta(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """b - a with the angles the short way round."""
        d = np.asarray(b, np.float64) - np.asarray(a, np.float64)
        return np.where(self.angle, _wrap(d), d)

    def clip(self, x: np.ndarray) -> np.ndarray:
        """Angles wrapped into [-pi, pi), other dims clipped into the box."""
        x = np.asarray(x, np.float64)
        return np.where(self.angle, _wrap(x), np.clip(x, self.low, self.high))

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return self.low + rng.random(self.dim) * (self.high - self.low)

    def steer(self, a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
        """The state at most ``step`` from ``a`` towards ``b`` (``b`` itself when closer)."""
        d = float(self.dist(a, b))
        if d <= step:
            return self.clip(b)
        return self.clip(a + self.delta(a, b) * (step / d))

    def features(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """float32 [N, feature_dim]: the network's inputs for (state, goal) pairs (broadcasting goals)."""
        s = np.atleast_2d(np.asarray(states, np.float64))
        g = np.broadcast_to(np.asarray(goals, np.float64), s.shape)
        return np.concatenate(
            [self._encode(s), self._encode(g), self.weights * self.delta(s, g) / self.diameter], axis=1
        ).astype(np.float32)

    def _encode(self, x: np.ndarray) -> np.ndarray:
        scaled = 2.0 * (x - self.low) / (self.high - self.low) - 1.0
        a = x[:, self.angle]
        return np.concatenate([scaled[:, ~self.angle], np.sin(a), np.cos(a)], axis=1)

    def densify(self, path: np.ndarray, step: float) -> np.ndarray:
        """The path with every segment cut into equal pieces of at most ``step`` (the search's motions)."""
        path = np.asarray(path, np.float64)
        out = [path[:1]]
        for a, b in zip(path[:-1], path[1:], strict=True):
            pieces = max(1, math.ceil(float(self.dist(a, b)) / step - 1e-9))
            t = np.arange(1, pieces + 1)[:, None] / pieces
            out.append(self.clip(a + t * self.delta(a, b)))
        return np.concatenate(out)


def _wrap(x: np.ndarray) -> np.ndarray:
    return (np.asarray(x, np.float64) + np.pi) % (2 * np.pi) - np.pi


# ------------------------------------------------------------------------------------------ the model
def _mlp(in_dim: int, out_dim: int, hidden: Sequence[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    prev = in_dim
    for h in hidden:
        layers += [nn.Linear(prev, int(h)), nn.SiLU()]
        prev = int(h)
    last = nn.Linear(prev, out_dim)
    with torch.no_grad():
        last.weight.mul_(0.1)
        last.bias.zero_()
    layers.append(last)
    return nn.Sequential(*layers)


class NEXTModel:
    """The policy (mean displacement, in step units per weighted dim) and value (cost-to-go / D) MLPs."""

    def __init__(
        self, space: ConfigSpace, hidden: Sequence[int] = (128, 128), lr: float = 1e-3, seed: int = 0
    ):
        self.space = space
        with torch.random.fork_rng():  # seeded weights without touching the caller's torch stream
            torch.manual_seed(int(seed))
            self.policy_net = _mlp(space.feature_dim, space.dim, hidden)
            self.value_net = _mlp(space.feature_dim, 1, hidden)
        params = [*self.policy_net.parameters(), *self.value_net.parameters()]
        self.optimizer = torch.optim.Adam(params, lr=lr)
        self.updates = 0

    @torch.no_grad()
    def predict(self, states: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(policy mean [N, d] in step units, value [N] in units of D) at ``states`` for ``goal``."""
        x = torch.from_numpy(self.space.features(states, goal))
        return self.policy_net(x).numpy().astype(np.float64), self.value_net(x)[:, 0].numpy().astype(
            np.float64
        )

    @torch.no_grad()
    def value(self, states: np.ndarray, goal: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(self.space.features(states, goal))
        return self.value_net(x)[:, 0].numpy().astype(np.float64)

    def fit(self, data: Dataset, steps: int, batch_size: int, rng: np.random.Generator) -> dict[str, float]:
        """``steps`` Adam steps on minibatches of ``data`` (drawn with ``rng``); the last losses."""
        x, u, v = (torch.from_numpy(a) for a in data.arrays())
        stats = {"policy_loss": float("nan"), "value_loss": float("nan")}
        if len(x) == 0:
            return stats
        for _ in range(int(steps)):
            idx = torch.from_numpy(rng.integers(0, len(x), size=min(int(batch_size), len(x))))
            policy_loss = ((self.policy_net(x[idx]) - u[idx]) ** 2).sum(1).mean()
            value_loss = ((self.value_net(x[idx])[:, 0] - v[idx]) ** 2).mean()
            self.optimizer.zero_grad()
            (policy_loss + value_loss).backward()
            self.optimizer.step()
            self.updates += 1
            stats = {"policy_loss": policy_loss.item(), "value_loss": value_loss.item()}
        return stats

    def state_dict(self) -> dict[str, Any]:
        return {
            "policy": copy.deepcopy(self.policy_net.state_dict()),
            "value": copy.deepcopy(self.value_net.state_dict()),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.policy_net.load_state_dict(state["policy"])
        self.value_net.load_state_dict(state["value"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.updates = int(state["updates"])


class Dataset:
    """Imitation pairs: features of (state, goal), policy target (next displacement), value target."""

    def __init__(self, space: ConfigSpace, step: float, hindsight: bool = True):
        self.space, self.step, self.hindsight = space, float(step), bool(hindsight)
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.paths = 0

    def add_path(self, path: np.ndarray, goal: np.ndarray) -> int:
        """Add the pairs of one solved path (start first, ending within the goal radius); their count."""
        sp = self.space
        w = sp.densify(path, self.step)
        if len(w) < 2:
            return 0
        seg = sp.dist(w[:-1], w[1:])
        to_end = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])  # remaining arc length per waypoint
        moves = sp.weights * sp.delta(w[:-1], w[1:]) / self.step  # [M, d] policy targets
        goal = np.asarray(goal, np.float64)
        last = float(sp.dist(w[-1], goal))
        xs = [sp.features(w[:-1], goal)]
        us = [moves]
        vs = [(to_end[:-1] + last) / sp.diameter]
        if self.hindsight:  # every later waypoint j as the goal of the sub-path i -> j
            m = len(w) - 1
            i, j = np.triu_indices(m, k=1)  # i < j <= m - 1 (j = m is the true goal's end, above)
            xs.append(sp.features(w[i], w[j]))
            us.append(moves[i])
            vs.append((to_end[i] - to_end[j]) / sp.diameter)
        chunk = (
            np.concatenate(xs).astype(np.float32),
            np.concatenate(us).astype(np.float32),
            np.concatenate(vs).astype(np.float32),
        )
        self.chunks.append(chunk)
        self.paths += 1
        return len(chunk[0])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if not self.chunks:
            f, d = self.space.feature_dim, self.space.dim
            return np.zeros((0, f), np.float32), np.zeros((0, d), np.float32), np.zeros(0, np.float32)
        if len(self.chunks) > 1:
            self.chunks = [tuple(np.concatenate(parts) for parts in zip(*self.chunks, strict=True))]
        return self.chunks[0]

    def __len__(self) -> int:
        return sum(len(c[0]) for c in self.chunks)

    def state_dict(self) -> dict[str, Any]:
        return {"arrays": tuple(a.copy() for a in self.arrays()), "paths": self.paths}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.chunks = [tuple(np.asarray(a).copy() for a in state["arrays"])]
        self.paths = int(state["paths"])


# ------------------------------------------------------------------------------------------ the search
@dataclass(frozen=True)
class SearchSettings:
    """One query's search (see the module docstring)."""

    step: float = 0.05  # steering step, in the env's distance
    max_iterations: int = 3000
    max_checks: int = 20000
    improve_iterations: int = 0  # iterations after the first solution (rewiring shortens the path)
    exploration: float = 1.0  # c of the UCB score
    uniform_share: float = 0.1  # iterations extending towards a uniform sample (RRT), with a model
    goal_bias: float = 0.05  # iterations extending towards the goal
    candidates: int = 10  # policy samples scored per guided expansion
    policy_std: float = 0.3  # the policy's std, in step units per weighted dim
    rewire_factor: float = 3.0  # choose-parent / rewire radius, in steps


@dataclass
class SearchResult:
    """One query: the best path found (to the tree node nearest the goal when unsolved)."""

    solved: bool
    path: np.ndarray  # [P, d], start first
    length: float  # the path's length in the env's distance (inf when unsolved)
    checks: int  # collision checks (motions) the query spent
    iterations: int
    nodes: int


class _Tree:
    """Growable arrays of tree states, parents, costs, values and kernel visit counts."""

    def __init__(self, root: np.ndarray, capacity: int = 256):
        d = len(root)
        self.states = np.zeros((capacity, d))
        self.parent = np.full(capacity, -1, np.int64)
        self.cost = np.zeros(capacity)
        self.value = np.zeros(capacity)
        self.w = np.zeros(capacity)
        self.terminal = np.zeros(capacity, bool)
        self.children: list[list[int]] = []
        self.n = 0
        self.attempts = np.zeros((capacity, d))
        self.a = 0
        self.add(root, -1, 0.0, 0.0, 1.0, False)

    def add(self, state, parent: int, cost: float, value: float, w: float, terminal: bool) -> int:
        if self.n == len(self.states):
            for name in ("states", "parent", "cost", "value", "w", "terminal"):
                old = getattr(self, name)
                new = np.zeros((2 * len(old), *old.shape[1:]), old.dtype)
                new[: len(old)] = old
                setattr(self, name, new)
        i = self.n
        self.states[i], self.parent[i], self.cost[i] = state, parent, cost
        self.value[i], self.w[i], self.terminal[i] = value, w, terminal
        self.children.append([])
        if parent >= 0:
            self.children[parent].append(i)
        self.n += 1
        return i

    def attempt(self, state: np.ndarray) -> None:
        if self.a == len(self.attempts):
            grown = np.zeros((2 * self.a, self.attempts.shape[1]))
            grown[: self.a] = self.attempts
            self.attempts = grown
        self.attempts[self.a] = state
        self.a += 1

    def reparent(self, i: int, parent: int, cost: float) -> None:
        self.children[self.parent[i]].remove(i)
        self.parent[i] = parent
        self.children[parent].append(i)
        drop = self.cost[i] - cost
        stack = [i]
        while stack:  # the whole subtree gets shorter by the same amount
            j = stack.pop()
            self.cost[j] -= drop
            stack.extend(self.children[j])

    def path_to(self, i: int) -> np.ndarray:
        idx = []
        while i >= 0:
            idx.append(i)
            i = int(self.parent[i])
        return self.states[idx[::-1]].copy()


def next_search(
    space: ConfigSpace,
    segments_collide: Callable[[np.ndarray, np.ndarray], np.ndarray],
    start: np.ndarray,
    goal: np.ndarray,
    goal_radius: float,
    settings: SearchSettings,
    rng: np.random.Generator,
    model: NEXTModel | None = None,
) -> SearchResult:
    """One NEXT query from ``start`` to within ``goal_radius`` of ``goal`` (see the module docstring).

    ``segments_collide(a, b)`` is the env's batched motion check ([N, d], [N, d] -> bool [N]); every
    motion asked about is one check. ``model=None``: every iteration samples uniformly (RRT*).
    """
    s = settings
    start, goal = np.asarray(start, np.float64), np.asarray(goal, np.float64)
    checks = 0

    def collide(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        nonlocal checks
        checks += len(a)
        return np.asarray(segments_collide(a, b), bool)

    def values(states: np.ndarray) -> np.ndarray:
        return np.zeros(len(states)) if model is None else -model.value(states, goal)

    h2 = s.step**2
    radius = s.rewire_factor * s.step
    tree = _Tree(start)
    tree.value[0] = values(start[None])[0]
    tree.attempt(start)
    best = 0 if float(space.dist(start, goal)) <= goal_radius else -1
    tree.terminal[0] = best == 0
    solved_at = 0 if best == 0 else None
    it = 0

    def kernel_sum(points: np.ndarray, around: np.ndarray) -> np.ndarray:
        """sum over ``around`` [A, d] of exp(-(d / step)^2), for each of ``points`` [K, d]."""
        d = space.dist(points[:, None, :], around[None, :, :])
        return np.exp(-(d**2) / h2).sum(axis=1)

    def insert(new: np.ndarray, via: int) -> int:
        """Add a state whose motion from node ``via`` is free: cheapest free parent, then rewire."""
        n = tree.n
        d = space.dist(tree.states[:n], new)
        parent, cost = via, tree.cost[via] + d[via]
        near = np.flatnonzero((d <= radius) & ~tree.terminal[:n])
        through = tree.cost[near] + d[near]
        for j in near[np.argsort(through, kind="stable")]:
            if tree.cost[j] + d[j] >= cost - 1e-12:
                break
            if not collide(tree.states[j][None], new[None])[0]:
                parent, cost = int(j), tree.cost[j] + d[j]
                break
        terminal = float(space.dist(new, goal)) <= goal_radius
        w = float(kernel_sum(new[None], tree.attempts[: tree.a])[0])
        i = tree.add(new, parent, cost, values(new[None])[0], w, terminal)
        near = np.flatnonzero((d <= radius) & (cost + d < tree.cost[:n] - 1e-12))
        near = near[near != parent]
        if len(near):
            free = ~collide(np.repeat(new[None], len(near), axis=0), tree.states[near])
            for j in near[free]:
                tree.reparent(int(j), i, cost + d[j])
        return i

    while it < s.max_iterations and checks < s.max_checks:
        if solved_at is not None and it - solved_at >= s.improve_iterations:
            break
        it += 1
        n = tree.n
        open_ = np.flatnonzero(~tree.terminal[:n])
        if not len(open_):
            break
        r = rng.random()
        if model is None or r < s.goal_bias + s.uniform_share:
            target = goal if r < s.goal_bias else space.sample(rng)
            via = int(open_[np.argmin(space.dist(tree.states[open_], target))])
        else:
            via, target = _guided_target(tree, open_, space, s, model, goal, rng, values, kernel_sum)
        new = space.steer(tree.states[via], target, s.step)
        if float(space.dist(tree.states[via], new)) < 1e-9:
            continue
        tree.w[:n] += np.exp(-(space.dist(tree.states[:n], new) ** 2) / h2)
        tree.attempt(new)
        if collide(tree.states[via][None], new[None])[0]:
            continue
        i = insert(new, via)
        if not tree.terminal[i] and float(space.dist(new, goal)) <= s.step and best < 0:
            if not collide(new[None], goal[None])[0]:  # the goal itself, one free motion away
                tree.w[: tree.n] += np.exp(-(space.dist(tree.states[: tree.n], goal) ** 2) / h2)
                tree.attempt(goal)
                i = insert(goal.copy(), i)
        goals = np.flatnonzero(tree.terminal[: tree.n])
        if len(goals):
            best = int(goals[np.argmin(tree.cost[goals])])
            if solved_at is None:
                solved_at = it
    return _search_result(tree, space, goal, best >= 0, checks, it)


def _guided_target(
    tree: _Tree,
    open_: np.ndarray,
    space: ConfigSpace,
    s: SearchSettings,
    model,
    goal,
    rng,
    values,
    kernel_sum,
) -> tuple[int, np.ndarray]:
    """NEXT's guided expansion: the open node with the highest UCB of its value, then the best-scored of
    the policy's candidate steps from it; (that node, the target to steer towards)."""
    n = tree.n
    log_w = math.log(float(tree.w[:n].sum()))
    ucb = tree.value[open_] + s.exploration * np.sqrt(log_w / tree.w[open_])
    via = int(open_[np.argmax(ucb)])
    mean, _ = model.predict(tree.states[via][None], goal)
    u = mean[0] + s.policy_std * rng.standard_normal((s.candidates, space.dim))
    cands = space.clip(tree.states[via] + u * s.step / space.weights)
    w = kernel_sum(cands, tree.attempts[: tree.a])
    score = values(cands) + s.exploration * np.sqrt(log_w / (1.0 + w))
    return via, cands[int(np.argmax(score))]


def _search_result(tree: _Tree, space: ConfigSpace, goal: np.ndarray, solved: bool, checks: int, it: int):
    """The cheapest path to a terminal node, or (unsolved) the path to the node nearest the goal."""
    if solved:
        goals = np.flatnonzero(tree.terminal[: tree.n])
        best = int(goals[np.argmin(tree.cost[goals])])
        path = tree.path_to(best)
        length = float(space.dist(path[:-1], path[1:]).sum()) if len(path) > 1 else 0.0
        return SearchResult(True, path, length, checks, it, tree.n)
    nearest = int(np.argmin(space.dist(tree.states[: tree.n], goal)))
    return SearchResult(False, tree.path_to(nearest), float("inf"), checks, it, tree.n)


def padded_paths(results: Sequence[SearchResult]) -> np.ndarray:
    """[N, P, d]: the results' paths, each padded by repeating its last state (zero-length motions), for
    ``path_metrics.score_paths``."""
    p = max(2, max(len(r.path) for r in results))
    out = []
    for r in results:
        tail = np.repeat(r.path[-1:], p - len(r.path), axis=0)
        out.append(np.concatenate([r.path, tail]))
    return np.stack(out)


# ------------------------------------------------------------------------------------------ training
@dataclass(frozen=True)
class TrainSettings:
    hidden: tuple[int, ...] = (128, 128)
    lr: float = 1e-3
    batch_size: int = 256
    hindsight: bool = True


def rrt_star_demonstrations(
    env, starts: np.ndarray, goals: np.ndarray, time_limit_s: float, seed: int = 0
) -> tuple[list[np.ndarray | None], int]:
    """RRT* (OMPL, ``time_limit_s`` per task) on the given tasks of a maze env: the solved paths (None
    where unsolved) and the collision checks they cost. Time-limited, so not reproducible bit for bit."""
    from .rrt_star import rrt_star_for_env

    rrt = rrt_star_for_env(env, time_limit_s=time_limit_s, seed=seed)
    radius = env.unwrapped.success_radius
    paths: list[np.ndarray | None] = []
    checks = 0
    for start, goal in zip(np.asarray(starts, np.float64), np.asarray(goals, np.float64), strict=True):
        result = rrt.plan(start, goal, radius)
        checks += result.collision_checks
        paths.append(result.path if result.solved else None)
    return paths, checks


class NEXTPlanner:
    """The search, its model and its training data, with every collision check counted.

    ``search`` answers one query with the model (``guided=False``: uniform, RRT*); ``imitate`` adds
    solved paths to the data; ``train`` fits the model; ``self_improve`` searches training tasks and
    imitates what it solved. ``checks`` counts every check spent (``add_checks`` adds outside ones, such
    as RRT*'s demonstrations). ``state_dict`` / ``load_state_dict`` continue exactly.
    """

    def __init__(
        self,
        space: ConfigSpace,
        segments_collide: Callable[[np.ndarray, np.ndarray], np.ndarray],
        goal_radius: float,
        search: SearchSettings = SearchSettings(),  # noqa: B008 - frozen
        train: TrainSettings = TrainSettings(),  # noqa: B008 - frozen
        seed: int = 0,
    ):
        self.space, self.segments_collide, self.goal_radius = space, segments_collide, float(goal_radius)
        self.search_settings, self.train_settings = search, train
        self.model = NEXTModel(space, train.hidden, train.lr, seed)
        self.data = Dataset(space, search.step, train.hindsight)
        self.rng = np.random.default_rng(seed)
        self.checks = 0

    @classmethod
    def for_env(cls, env, search: SearchSettings, train: TrainSettings, seed: int = 0) -> NEXTPlanner:
        maze = env.unwrapped
        return cls(ConfigSpace.from_env(env), maze.segments_collide, maze.success_radius, search, train, seed)

    def add_checks(self, n: int) -> None:
        self.checks += int(n)

    def search(
        self, start, goal, *, guided: bool = True, rng: np.random.Generator | None = None, **overrides
    ) -> SearchResult:
        """One query (``overrides``: SearchSettings fields for this query); its checks are counted."""
        settings = self.search_settings if not overrides else _replace(self.search_settings, overrides)
        result = next_search(
            self.space,
            self.segments_collide,
            start,
            goal,
            self.goal_radius,
            settings,
            self.rng if rng is None else rng,
            self.model if guided else None,
        )
        self.checks += result.checks
        return result

    def imitate(self, paths: Sequence[np.ndarray | None], goals: np.ndarray) -> int:
        """Add the solved ``paths`` (None: skipped) for their ``goals``; the number added."""
        added = 0
        for path, goal in zip(paths, goals, strict=True):
            if path is not None and len(path) >= 2:
                self.data.add_path(path, goal)
                added += 1
        return added

    def train(self, steps: int) -> dict[str, float]:
        return self.model.fit(self.data, steps, self.train_settings.batch_size, self.rng)

    def self_improve(
        self, starts: np.ndarray, goals: np.ndarray, steps: int, improve_iterations: int | None = None
    ) -> dict[str, float]:
        """Search each training task with the model (``improve_iterations``: after its first solution,
        default the search settings'), imitate the solved paths, train ``steps``."""
        more = {} if improve_iterations is None else {"improve_iterations": int(improve_iterations)}
        results = [self.search(s, g, **more) for s, g in zip(starts, goals, strict=True)]
        self.imitate([r.path if r.solved else None for r in results], goals)
        stats = self.train(steps)
        return {**stats, "solved": float(np.mean([r.solved for r in results])) if results else float("nan")}

    def state_dict(self) -> dict[str, Any]:
        return {
            "model": self.model.state_dict(),
            "data": self.data.state_dict(),
            "rng": copy.deepcopy(self.rng.bit_generator.state),
            "checks": self.checks,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.model.load_state_dict(state["model"])
        self.data.load_state_dict(state["data"])
        self.rng.bit_generator.state = copy.deepcopy(state["rng"])
        self.checks = int(state["checks"])


def _replace(settings: SearchSettings, overrides: dict[str, Any]) -> SearchSettings:
    unknown = sorted(set(overrides) - set(asdict(settings)))
    if unknown:
        raise ValueError(f"unknown search settings {unknown}; known: {sorted(asdict(settings))}")
    return SearchSettings(**{**asdict(settings), **overrides})
