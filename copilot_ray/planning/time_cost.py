"""D_tau and the learned time-cost model tau_hat (paper Sec. 3.3, 3.4, 4.1).

``TimeCostDataset`` is D_tau: a bounded ring buffer of tuples (start, end, cost). Costs are in DISTANCE
units (steps times the environment's nominal step distance; see ``segment_cost``), so the 50,000
Euclidean initial tuples of Sec. 4.1 and the measured tuples share one scale.

``TimeCostModel`` is a small regression MLP on D_tau with a positive (softplus) output.

Why the measured tuples come to outweigh the Euclidean ones (the choice of capacity and sampling):
the paper warm-starts D_tau with 50,000 Euclidean tuples but wants the cost to become the agent's time
cost. One repetition of Algorithm 3 with 30 tasks and K = 5 yields 30 * 63 = 1,890 measured tuples, so
one training iteration (b = 5) yields about 9,500. The ring buffer evicts the oldest tuples first, i.e.
the Euclidean ones: with the default capacity of 100,000 the measured tuples are the majority after about
5-6 iterations and the Euclidean ones are gone after about 11. ``recent_fraction`` (default 0.25) draws
that share of every training batch from the ``recent_window`` most recent tuples, so fresh measurements,
which also track the improving agent, influence the fit from the first refit on, while the rest of the
batch keeps the Euclidean prior for regions the agent has not visited yet.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from .planner import _as_rng
from .segment_cost import euclidean_distance

__all__ = ["TimeCostDataset", "TimeCostModel"]


class TimeCostDataset:
    """Bounded FIFO ring buffer of (start [d], end [d], cost) tuples (D_tau).

    Args:
        goal_dim: d.
        capacity: maximal number of tuples; the oldest are overwritten first.
        recent_fraction: share of each ``sample`` drawn from the ``recent_window`` newest tuples.
        recent_window: size of that window.
    """

    def __init__(
        self,
        goal_dim: int,
        capacity: int = 100_000,
        recent_fraction: float = 0.25,
        recent_window: int = 10_000,
    ) -> None:
        if int(goal_dim) < 1:
            raise ValueError(f"goal_dim must be >= 1, got goal_dim={goal_dim!r}")
        if int(capacity) < 1:
            raise ValueError(f"capacity must be >= 1, got capacity={capacity!r}")
        if not 0.0 <= float(recent_fraction) <= 1.0:
            raise ValueError(f"recent_fraction must lie in [0, 1], got recent_fraction={recent_fraction!r}")
        if int(recent_window) < 1:
            raise ValueError(f"recent_window must be >= 1, got recent_window={recent_window!r}")
        self.goal_dim = int(goal_dim)
        self.capacity = int(capacity)
        self.recent_fraction = float(recent_fraction)
        self.recent_window = int(recent_window)
        self.starts = np.zeros((self.capacity, self.goal_dim), np.float32)
        self.ends = np.zeros((self.capacity, self.goal_dim), np.float32)
        self.costs = np.zeros(self.capacity, np.float32)
        self._next = 0  # slot the next tuple goes to
        self._size = 0
        self.num_added = 0  # lifetime count

    def __len__(self) -> int:
        return self._size

    def add(self, starts, ends, costs) -> None:
        """Append tuples ``starts [N, d]``, ``ends [N, d]``, ``costs [N]`` (distance units)."""
        starts = np.asarray(starts, np.float32).reshape(-1, self.goal_dim)
        ends = np.asarray(ends, np.float32).reshape(-1, self.goal_dim)
        costs = np.asarray(costs, np.float32).reshape(-1)
        n = starts.shape[0]
        if ends.shape[0] != n or costs.shape[0] != n:
            raise ValueError(f"add: got {n} starts, {ends.shape[0]} ends and {costs.shape[0]} costs")
        if not np.all(np.isfinite(costs)):
            raise ValueError("add: costs must be finite")
        if n == 0:
            return
        if n > self.capacity:  # only the newest `capacity` survive anyway
            starts, ends, costs = starts[-self.capacity :], ends[-self.capacity :], costs[-self.capacity :]
            self.num_added += n - self.capacity
            n = self.capacity
        slots = (self._next + np.arange(n)) % self.capacity
        self.starts[slots] = starts
        self.ends[slots] = ends
        self.costs[slots] = costs
        self._next = int((self._next + n) % self.capacity)
        self._size = min(self._size + n, self.capacity)
        self.num_added += n

    def init_euclidean(
        self,
        n: int = 50_000,
        low=0.0,
        high=1.0,
        rng=None,
        distance_fn: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    ) -> None:
        """Add ``n`` uniform random pairs in the box ``[low, high]`` with cost = their distance (Sec. 4.1)."""
        rng = _as_rng(rng)
        low = np.broadcast_to(np.asarray(low, np.float64), (self.goal_dim,))
        high = np.broadcast_to(np.asarray(high, np.float64), (self.goal_dim,))
        a = rng.uniform(low, high, size=(int(n), self.goal_dim))
        b = rng.uniform(low, high, size=(int(n), self.goal_dim))
        self.add(a, b, (distance_fn or euclidean_distance)(a, b))

    def _chronological(self, idx: np.ndarray) -> np.ndarray:
        """Map positions 0..size-1 (oldest first) to buffer slots."""
        oldest = (self._next - self._size) % self.capacity
        return (oldest + idx) % self.capacity

    def sample(self, n: int, rng=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``n`` tuples with replacement: ``recent_fraction`` of them from the newest window."""
        if self._size == 0:
            raise ValueError("cannot sample from an empty TimeCostDataset")
        rng = _as_rng(rng)
        n = int(n)
        n_recent = int(round(n * self.recent_fraction))
        window = min(self.recent_window, self._size)
        pos = np.concatenate(
            [
                rng.integers(0, self._size, size=n - n_recent),
                rng.integers(self._size - window, self._size, size=n_recent),
            ]
        )
        slots = self._chronological(pos)
        return self.starts[slots], self.ends[slots], self.costs[slots]

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All stored tuples, oldest first (copies)."""
        slots = self._chronological(np.arange(self._size))
        return self.starts[slots], self.ends[slots], self.costs[slots]

    def state_dict(self) -> dict:
        s, e, c = self.arrays()
        return {
            "goal_dim": self.goal_dim,
            "capacity": self.capacity,
            "recent_fraction": self.recent_fraction,
            "recent_window": self.recent_window,
            "starts": s,
            "ends": e,
            "costs": c,
            "num_added": self.num_added,
        }

    def load_state_dict(self, state: dict) -> None:
        if int(state["goal_dim"]) != self.goal_dim:
            raise ValueError(f"state has goal_dim={state['goal_dim']}, this dataset has {self.goal_dim}")
        self.__init__(self.goal_dim, state["capacity"], state["recent_fraction"], state["recent_window"])
        self.add(state["starts"], state["ends"], state["costs"])
        self.num_added = int(state["num_added"])


class TimeCostModel:
    """tau_hat(a, b): regression MLP on features ``[a, b, b - a, ||b - a||]`` with softplus output.

    Args:
        goal_dim: d.
        low, high: goal bounds used to scale the inputs to about ``[-1, 1]`` (None: no scaling).
        hidden: hidden sizes (ReLU).
        lr: Adam learning rate.
        loss: ``"huber"`` (default; robust to tau_max time-outs) or ``"mse"``.
        huber_beta: transition point of the Huber loss, in distance units.
        step_distance: the environment's nominal distance per step, used by ``add_steps`` to turn
            measured step counts into distance units.
        dataset: an existing D_tau to use, else one is created with ``capacity`` etc.
    """

    def __init__(
        self,
        goal_dim: int,
        low=None,
        high=None,
        *,
        hidden=(64, 64),
        lr: float = 1e-3,
        loss: str = "huber",
        huber_beta: float = 0.1,
        step_distance: float = 1.0,
        capacity: int = 100_000,
        recent_fraction: float = 0.25,
        recent_window: int = 10_000,
        dataset: TimeCostDataset | None = None,
        seed: int | None = 0,
    ) -> None:
        if loss not in ("huber", "mse"):
            raise ValueError(f"loss must be 'huber' or 'mse', got loss={loss!r}")
        if float(step_distance) <= 0:
            raise ValueError(f"step_distance must be > 0, got step_distance={step_distance!r}")
        self.goal_dim = int(goal_dim)
        self.loss_kind = loss
        self.huber_beta = float(huber_beta)
        self.step_distance = float(step_distance)
        self.hidden = tuple(int(h) for h in hidden)
        self.lr = float(lr)
        self.dataset = dataset or TimeCostDataset(goal_dim, capacity, recent_fraction, recent_window)
        if low is not None:
            low = np.broadcast_to(np.asarray(low, np.float32), (self.goal_dim,))
            high = np.broadcast_to(np.asarray(high, np.float32), (self.goal_dim,))
            center, half = (low + high) / 2, (high - low) / 2
        else:
            center, half = np.zeros(self.goal_dim, np.float32), np.ones(self.goal_dim, np.float32)
        self.low, self.high = low, high
        self._center = torch.as_tensor(center, dtype=torch.float32)
        self._half = torch.as_tensor(half, dtype=torch.float32)
        if seed is not None:
            gen_state = torch.random.get_rng_state()
            torch.manual_seed(seed)
        layers: list[nn.Module] = []
        prev = 3 * self.goal_dim + 1
        for h in self.hidden:
            layers += [nn.Linear(prev, h), nn.ReLU()]
            prev = h
        layers.append(nn.Linear(prev, 1))
        self.net = nn.Sequential(*layers)
        if seed is not None:
            torch.random.set_rng_state(gen_state)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=self.lr)

    def _forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        an = (a - self._center) / self._half
        bn = (b - self._center) / self._half
        diff = b - a
        dist = torch.linalg.vector_norm(diff, dim=-1, keepdim=True)
        x = torch.cat([an, bn, diff / self._half, dist], dim=-1)
        return F.softplus(self.net(x)).squeeze(-1)

    def predict(self, a, b) -> np.ndarray:
        """tau_hat for ``[N, d]`` endpoint arrays -> numpy ``[N]`` (distance units, no grad)."""
        with torch.no_grad():
            out = self._forward(
                torch.as_tensor(np.asarray(a), dtype=torch.float32),
                torch.as_tensor(np.asarray(b), dtype=torch.float32),
            )
        return out.numpy().astype(np.float64)

    __call__ = predict

    def add(self, starts, ends, costs) -> None:
        """Add tuples with costs already in distance units."""
        self.dataset.add(starts, ends, costs)

    def add_steps(self, starts, ends, steps) -> None:
        """Add measured tuples whose cost is a step count (converted with ``step_distance``)."""
        self.dataset.add(starts, ends, np.asarray(steps, np.float64) * self.step_distance)

    def init_euclidean(self, n: int = 50_000, low=None, high=None, rng=None, distance_fn=None) -> None:
        low = self.low if low is None else low
        high = self.high if high is None else high
        if low is None or high is None:
            raise ValueError("init_euclidean needs goal bounds low/high")
        self.dataset.init_euclidean(n, low, high, rng, distance_fn)

    def fit(self, num_steps: int = 100, batch_size: int = 256, rng=None) -> float:
        """``num_steps`` Adam steps on mini-batches from D_tau; returns the mean loss over the steps."""
        rng = _as_rng(rng)
        total = 0.0
        for _ in range(int(num_steps)):
            s, e, c = self.dataset.sample(batch_size, rng)
            pred = self._forward(torch.as_tensor(s), torch.as_tensor(e))
            target = torch.as_tensor(c)
            if self.loss_kind == "huber":
                loss = F.smooth_l1_loss(pred, target, beta=self.huber_beta)
            else:
                loss = F.mse_loss(pred, target)
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.optimizer.step()
            total += float(loss.detach())
        return total / max(int(num_steps), 1)

    def evaluate(self, n: int = 4096, rng=None) -> float:
        """Mean squared error on ``n`` tuples drawn from D_tau (no update)."""
        s, e, c = self.dataset.sample(n, rng)
        return float(np.mean((self.predict(s, e) - c) ** 2))

    def state_dict(self) -> dict:
        return {
            "net": copy.deepcopy(self.net.state_dict()),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
            "dataset": self.dataset.state_dict(),
            "step_distance": self.step_distance,
        }

    def load_state_dict(self, state: dict) -> None:
        self.net.load_state_dict(state["net"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.dataset.load_state_dict(state["dataset"])
        self.step_distance = float(state["step_distance"])
