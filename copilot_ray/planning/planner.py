"""The sub-goal planning policy pi_p(g | g_i, g_j) (paper Sec. 3.3, Eq. 7 and 10).

Follows the SGT-PG planner that the paper's public code copies (Shuang-AO/CO-PILOT, tomjur/SGT-PG):

* one small MLP per tree layer (``shared_across_layers=False``, the default) or one for all layers;
* Gaussian with mean ``(g_i + g_j) / 2 + MLP([g_i, g_j])`` and a fixed standard deviation (0.05);
  the MLP's last layer starts near zero, so the initial policy proposes (noisy) midpoints;
* the exploration noise is ``noise="absolute"`` (the reference code: ``std`` in goal units at every
  layer) or ``noise="relative"`` (``std`` times the length of the parent segment ``g_i -> g_j``, so a
  layer-5 sub-goal between points 0.06 apart is not thrown 0.05 off, as with the absolute std, while a
  layer-1 sub-goal still explores widely; floored at ``MIN_STD``). ``set_std`` changes ``std`` between
  updates (annealing); the log-density always uses the std the tree was sampled with, because an update
  follows its sampling directly;
* sampled sub-goals are clipped into the goal box ``[low, high]``. The log-density is that of the
  unclipped Gaussian evaluated at the (clipped) stored sub-goal, as in the reference code; with the
  default std 0.05 clipping only matters at the very edge of the box;
* the baseline of the policy gradient is the mean cost of the repeated samples of the same task;
* PPO with the *standard* clipped surrogate (the reference code's clip is broken), clip 0.2, Adam
  lr 0.005 (paper Sec. 4.1).

Scaling: when goal bounds are known the MLP sees its inputs mapped to ``[-1, 1]`` per dimension and its
output is multiplied by the half-width of the box, so the same learning rate behaves alike on goal spaces
of different extent (on ``[-1, 1]^d``, the reference setting, both maps are the identity).

The class holds torch modules but takes and returns numpy arrays except for ``log_prob``, which returns a
differentiable torch tensor. Sampling noise comes from a ``numpy.random.Generator`` so runs are seeded the
same way as the rest of the project.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from copilot_ray.torch_checks import all_finite

from .planner_modes import ANGLE_MODES, MEAN_MODES, NOISE_MODES
from .subgoal_tree import check_depth, depth_of, empty_tree, new_layer_indices, parent_indices

__all__ = ["SubgoalPlanner", "group_baseline"]

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
LEAK = 0.01
MIN_STD = 1e-3  # floor of a relative std (goal units): a zero-length parent segment keeps a density


def _as_rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(rng)


def _tidx(idx: np.ndarray) -> torch.Tensor:
    """Index array as a torch tensor (the cached numpy index arrays are read-only)."""
    return torch.from_numpy(np.array(idx, dtype=np.int64))


def group_baseline(costs: np.ndarray, group_ids: np.ndarray | None) -> np.ndarray:
    """Per-row baseline: the mean cost of the rows with the same group id (the global mean if None)."""
    costs = np.asarray(costs, dtype=np.float64)
    if group_ids is None:
        return np.full_like(costs, costs.mean())
    group_ids = np.asarray(group_ids)
    if group_ids.shape != costs.shape:
        raise ValueError(f"group_ids shape {group_ids.shape} must match costs shape {costs.shape}")
    _, inverse = np.unique(group_ids, return_inverse=True)
    sums = np.bincount(inverse, weights=costs)
    counts = np.bincount(inverse)
    return (sums / counts)[inverse]


def _mlp(in_dim: int, out_dim: int, hidden: Sequence[int], last_init_scale: float) -> nn.Sequential:
    layers: list[nn.Module] = []
    prev = in_dim
    for h in hidden:
        layers += [nn.Linear(prev, h), nn.Tanh()]
        prev = h
    last = nn.Linear(prev, out_dim)
    with torch.no_grad():
        last.weight.mul_(last_init_scale)
        last.bias.zero_()
    layers.append(last)
    return nn.Sequential(*layers)


class SubgoalPlanner:
    """Gaussian sub-goal policy for trees up to depth ``depth``.

    Args:
        goal_dim: dimension d of the goal space.
        depth: maximal tree depth K (one network per layer 1..K unless shared).
        low, high: goal-space bounds (arrays [d] or scalars); sub-goals are clipped into them. ``None``
            means unbounded (no clipping, no input/output scaling).
        hidden: hidden sizes of each MLP (tanh).
        std: standard deviation (scalar or [d]): in goal units with ``noise="absolute"``, a fraction of
            the parent segment's length with ``noise="relative"``.
        noise: "absolute" (the reference code) or "relative" (see the module docstring).
        shared_across_layers: one MLP for all layers instead of one per layer.
        lr, clip_eps, epochs: Adam learning rate, PPO clip range and PPO epochs per ``update``.
        max_grad_norm: optional gradient-norm clip (None: off, as in the reference).
        target_kl: stop an ``update``'s epochs early once the approximate KL between the sampling
            policy and the current one exceeds 1.5 x this (as SB3's PPO); None: run all epochs.
        max_kl: undo an ``update`` (weights and optimiser state) whose final approximate KL from the
            sampling policy exceeds this, as a trust-region line search rejects a step; None: never.
        normalize_advantages: divide the baselined advantages by their standard deviation.
        augment_reversed: ask ``construct_trees`` to also train on every sample with start and goal
            swapped (the reference code does this); costs of reversed trees are re-evaluated there, so an
            asymmetric time cost stays correct.
        angle_dims: goal dims that are angles in [-pi, pi): a sub-goal's base is the short-way midpoint of
            its parents (not the raw mean, which flips the body half a turn across the seam), samples are
            wrapped rather than clipped, and densities use the wrapped difference.
        std_scale: per-dim factor on ``std`` ([d]; default ones): with a distance that weights dims
            differently (an angle as far as the body's tip moves), ``1 / weight`` makes the exploration
            the same size in distance units in every dim.
        mean: "free" (the reference code), "squashed" into the goal box or "leaky" outside it (see
            MEAN_MODES; angle dims, which wrap, and an unbounded planner are never bounded).
        seed: seed of the torch initialisation.
    """

    @classmethod
    def from_settings(
        cls,
        settings: Mapping[str, Any],
        goal_dim: int,
        depth: int,
        low,
        high,
        seed: int | None = 0,
        *,
        geometry: Any = None,
        angle_dims: Sequence[int] = (),
        std_scale: Sequence[float] | None = None,
    ) -> SubgoalPlanner:
        """pi_p from a `planner` settings dict (the `planner.*` settings of CO-PILOT: hidden, std, noise,
        lr, clip, epochs, max_grad_norm, target_kl, max_kl, mean, angles; the others steer the algorithm, not
        pi_p). `geometry` (an env's agent geometry: `angle_dims`, `distance_weights`) applies
        `settings["angles"]`; without it `angle_dims` and `std_scale` are used as given."""
        mode = settings.get("angles", "raw")
        if mode not in ANGLE_MODES:
            raise ValueError(f"angles must be one of {ANGLE_MODES}, got {mode!r}")
        if geometry is not None and mode != "raw":
            angle_dims = tuple(geometry.angle_dims)
            if mode == "scaled":
                std_scale = 1.0 / np.asarray(geometry.distance_weights, np.float64)
        return cls(
            goal_dim,
            depth,
            low,
            high,
            hidden=tuple(settings["hidden"]),
            std=settings["std"],
            noise=settings["noise"],
            lr=settings["lr"],
            clip_eps=settings["clip"],
            epochs=settings["epochs"],
            max_grad_norm=settings["max_grad_norm"],
            target_kl=settings["target_kl"],
            max_kl=settings["max_kl"],
            mean=settings.get("mean", "free"),
            angle_dims=angle_dims,
            std_scale=std_scale,
            seed=seed,
        )

    def __init__(
        self,
        goal_dim: int,
        depth: int,
        low=None,
        high=None,
        *,
        hidden: Sequence[int] = (20, 20, 20),
        std: float | Sequence[float] = 0.05,
        noise: str = "absolute",
        shared_across_layers: bool = False,
        lr: float = 0.005,
        clip_eps: float = 0.2,
        epochs: int = 4,
        max_grad_norm: float | None = None,
        target_kl: float | None = None,
        max_kl: float | None = None,
        normalize_advantages: bool = True,
        augment_reversed: bool = False,
        last_init_scale: float = 0.01,
        angle_dims: Sequence[int] = (),
        std_scale: Sequence[float] | None = None,
        mean: str = "free",
        seed: int | None = 0,
    ) -> None:
        _check_planner_args(goal_dim, low, high, noise, clip_eps, epochs, target_kl, max_kl)
        if mean not in MEAN_MODES:
            raise ValueError(f"mean must be one of {MEAN_MODES}, got mean={mean!r}")
        self.goal_dim = int(goal_dim)
        self.depth = check_depth(depth)
        self.low, self.high = _bounds(low, high, self.goal_dim)
        self.noise = noise
        self.angle_dims = tuple(int(i) for i in angle_dims)
        if any(not 0 <= i < self.goal_dim for i in self.angle_dims):
            raise ValueError(f"angle_dims must index the {self.goal_dim} goal dims, got {angle_dims!r}")
        self._angle = np.zeros(self.goal_dim, bool)
        self._angle[list(self.angle_dims)] = True
        self._angle_t = torch.as_tensor(self._angle)
        scale = np.ones(self.goal_dim) if std_scale is None else np.asarray(std_scale, np.float64)
        if scale.shape != (self.goal_dim,) or not np.all(np.isfinite(scale) & (scale > 0)):
            raise ValueError(f"std_scale must be {self.goal_dim} positive numbers, got {std_scale!r}")
        self.std_scale = scale.astype(np.float32)
        self.set_std(std)
        self.hidden = tuple(int(h) for h in hidden)
        self.shared_across_layers = bool(shared_across_layers)
        self.lr = float(lr)
        self.clip_eps = float(clip_eps)
        self.epochs = int(epochs)
        self.max_grad_norm = None if max_grad_norm is None else float(max_grad_norm)
        self.target_kl = None if target_kl is None else float(target_kl)
        self.max_kl = None if max_kl is None else float(max_kl)
        self.normalize_advantages = bool(normalize_advantages)
        self.augment_reversed = bool(augment_reversed)
        self.last_init_scale = float(last_init_scale)
        self.nets = self._build_nets(seed)
        self.optimizer = torch.optim.Adam(self.nets.parameters(), lr=self.lr)
        # The nets see endpoints mapped to [-1, 1] ((x - center) / half) and their output is scaled by half;
        # the mean is free unless mean="squashed" (samples are clipped into the box in `extend`). Unbounded: unit box.
        center = (self.low + self.high) / 2.0 if self.low is not None else np.zeros(self.goal_dim, np.float32)
        half = (self.high - self.low) / 2.0 if self.low is not None else np.ones(self.goal_dim, np.float32)
        self._center = torch.as_tensor(center, dtype=torch.float32)
        self._half = torch.as_tensor(half, dtype=torch.float32)
        self.mean_mode = mean
        # the dims a bounded mean is kept at the box on (None: free, or nothing to bound), and the box
        bounded = ~self._angle if mean != "free" and self.low is not None else np.zeros(self.goal_dim, bool)
        self._bounded_dims = torch.as_tensor(bounded) if bounded.any() else None
        self._box_low, self._box_high = self._center - self._half, self._center + self._half

    def _build_nets(self, seed: int | None) -> nn.ModuleList:
        """One MLP per layer (or one shared), initialised from `seed` without touching torch's global RNG."""
        if seed is not None:
            gen_state = torch.random.get_rng_state()
            torch.manual_seed(seed)
        n_nets = 1 if self.shared_across_layers else self.depth
        nets = nn.ModuleList(
            _mlp(2 * self.goal_dim, self.goal_dim, self.hidden, self.last_init_scale) for _ in range(n_nets)
        )
        if seed is not None:
            torch.random.set_rng_state(gen_state)
        return nets

    def set_std(self, std: float | Sequence[float]) -> None:
        """Sets the exploration std (scalar or [d]; its meaning depends on ``noise``)."""
        std_arr = np.broadcast_to(np.asarray(std, dtype=np.float32), (self.goal_dim,)).copy()
        if not np.all(std_arr > 0):
            raise ValueError(f"std must be > 0, got std={std!r}")
        self.std = std_arr  # as set (what checkpoints store); the noise is std * std_scale
        self._std_t = torch.as_tensor(self.std * self.std_scale, dtype=torch.float32)

    # ------------------------------------------------------------------ config / persistence
    def config(self) -> dict:
        return {
            "goal_dim": self.goal_dim,
            "depth": self.depth,
            "low": None if self.low is None else self.low.tolist(),
            "high": None if self.high is None else self.high.tolist(),
            "hidden": list(self.hidden),
            "std": self.std.tolist(),
            "noise": self.noise,
            "shared_across_layers": self.shared_across_layers,
            "lr": self.lr,
            "clip_eps": self.clip_eps,
            "epochs": self.epochs,
            "max_grad_norm": self.max_grad_norm,
            "target_kl": self.target_kl,
            "max_kl": self.max_kl,
            "normalize_advantages": self.normalize_advantages,
            "augment_reversed": self.augment_reversed,
            "last_init_scale": self.last_init_scale,
            "angle_dims": list(self.angle_dims),
            "std_scale": self.std_scale.tolist(),
            "mean": self.mean_mode,
        }

    def state_dict(self) -> dict:
        return {
            "config": self.config(),
            "nets": copy.deepcopy(self.nets.state_dict()),
            "optimizer": copy.deepcopy(self.optimizer.state_dict()),
        }

    def load_state_dict(self, state: dict) -> None:
        # The std is state too: an annealed planner resumes with the std it had.
        self.set_std(state["config"]["std"])
        self.nets.load_state_dict(state["nets"])
        self.optimizer.load_state_dict(state["optimizer"])

    @classmethod
    def from_state_dict(cls, state: dict) -> SubgoalPlanner:
        planner = cls(**state["config"], seed=None)
        planner.load_state_dict(state)
        return planner

    def parameters(self):
        return self.nets.parameters()

    # ------------------------------------------------------------------ the Gaussian
    def _net(self, k: int) -> nn.Module:
        return self.nets[0] if self.shared_across_layers else self.nets[k - 1]

    def _check_trees(self, trees) -> int:
        K = depth_of(trees)
        if K > self.depth:
            raise ValueError(f"trees of depth {K} exceed the planner's depth {self.depth}")
        if trees.shape[-1] != self.goal_dim:
            raise ValueError(f"trees have goal_dim {trees.shape[-1]}, the planner expects {self.goal_dim}")
        return K

    def mean(self, left: torch.Tensor, right: torch.Tensor, k: int) -> torch.Tensor:
        """Mean sub-goal of layer k's policy between endpoints ``left``/``right`` [..., d] (torch)."""
        x = torch.cat([(left - self._center) / self._half, (right - self._center) / self._half], dim=-1)
        base = (left + right) / 2.0
        if self.angle_dims:  # the short way round: left + wrap(right - left) / 2
            base = torch.where(self._angle_t, left + _wrap_t(right - left) / 2.0, base)
        mean = base + self._net(k)(x) * self._half
        if self._bounded_dims is not None:
            if self.mean_mode == "squashed":
                bounded = self._center + self._half * torch.tanh((mean - self._center) / self._half)
            else:  # leaky
                inside = torch.clamp(mean, self._box_low, self._box_high)
                bounded = inside + LEAK * (mean - inside)
            mean = torch.where(self._bounded_dims, bounded, mean)
        return mean

    def _layer_mean(self, trees_t: torch.Tensor, K: int, k: int) -> torch.Tensor:
        li, ri = parent_indices(K, k)
        return self.mean(trees_t[:, _tidx(li)], trees_t[:, _tidx(ri)], k)

    def _layer_std(self, trees_t: torch.Tensor, K: int, k: int) -> torch.Tensor:
        """Std of each of layer k's new sub-goals: ``[d]`` (absolute) or ``[B, 2^(k-1), d]`` (relative)."""
        if self.noise == "absolute":
            return self._std_t
        li, ri = parent_indices(K, k)
        parent = torch.linalg.vector_norm(trees_t[:, _tidx(ri)] - trees_t[:, _tidx(li)], dim=-1, keepdim=True)
        return torch.clamp(parent * self._std_t, min=MIN_STD)

    def extend(self, trees: np.ndarray, k: int, deterministic: bool = False, rng=None) -> np.ndarray:
        """Fill layer k of ``trees`` in place (layers < k must be filled) and return them."""
        K = self._check_trees(trees)
        li, ri = parent_indices(K, k)
        mid = new_layer_indices(K, k)
        if np.isnan(trees[:, li]).any() or np.isnan(trees[:, ri]).any():
            raise ValueError(f"layer {k} needs layers 0..{k - 1} filled first (found NaN parents)")
        with torch.no_grad():
            trees_t = torch.as_tensor(trees, dtype=torch.float32)
            mu = self._layer_mean(trees_t, K, k).numpy()
            std = None if deterministic else self._layer_std(trees_t, K, k).numpy()
        if not deterministic:
            rng = _as_rng(rng)
            mu = mu + rng.standard_normal(mu.shape).astype(np.float32) * std
        if self.angle_dims:  # angles wrap instead of being clipped (an angle's bounds are its seam)
            mu[..., self._angle] = np.mod(mu[..., self._angle] + np.pi, 2 * np.pi) - np.pi
        if self.low is not None:
            mu = np.clip(mu, self.low, self.high)
        trees[:, mid] = mu
        return trees

    def sample(
        self,
        starts,
        goals,
        depth: int | None = None,
        upto_layer: int | None = None,
        deterministic: bool = False,
        rng=None,
    ) -> np.ndarray:
        """Sample trees ``[B, 2^K + 1, d]`` (K = ``depth`` or the planner's), layers 1..upto_layer.

        Layers deeper than ``upto_layer`` stay NaN. ``deterministic=True`` takes the mean at every node.
        """
        K = self.depth if depth is None else check_depth(depth)
        if K > self.depth:
            raise ValueError(f"depth {K} exceeds the planner's depth {self.depth}")
        upto = K if upto_layer is None else int(upto_layer)
        if not 0 <= upto <= K:
            raise ValueError(f"upto_layer must lie in [0, {K}], got upto_layer={upto_layer!r}")
        trees = empty_tree(starts, goals, K)
        rng = None if deterministic else _as_rng(rng)
        for k in range(1, upto + 1):
            self.extend(trees, k, deterministic=deterministic, rng=rng)
        return trees

    def log_prob(self, trees, layers: int | Iterable[int]) -> torch.Tensor:
        """Sum of the log-densities of the midpoints of the given layers: torch ``[B]`` (differentiable).

        ``layers`` is an iterable of layer indices (>= 1) or an int k meaning layers 1..k.
        """
        trees_t = torch.as_tensor(np.asarray(trees), dtype=torch.float32)
        K = self._check_trees(trees_t)
        if isinstance(layers, int | np.integer):
            layers = range(1, int(layers) + 1)
        total = torch.zeros(trees_t.shape[0])
        for k in layers:
            mid = new_layer_indices(K, k)
            mu = self._layer_mean(trees_t, K, k)
            std = self._layer_std(trees_t, K, k)
            diff = trees_t[:, _tidx(mid)] - mu
            if self.angle_dims:
                diff = torch.where(self._angle_t, _wrap_t(diff), diff)
            z = diff / std
            log_std = torch.log(std).expand_as(z).sum(dim=(1, 2))
            n_terms = len(mid) * self.goal_dim
            total = total - 0.5 * (z * z).sum(dim=(1, 2)) - log_std - n_terms * _LOG_SQRT_2PI
        return total

    # ------------------------------------------------------------------ learning
    def update(
        self,
        trees: np.ndarray,
        costs: np.ndarray,
        upto_layer: int,
        group_ids: np.ndarray | None = None,
        epochs: int | None = None,
    ) -> dict[str, float]:
        """One PPO update minimising the cost of the sampled trees over layers 1..upto_layer.

        Args:
            trees: ``[N, 2^K + 1, d]`` trees sampled from the current policy (layers 1..upto_layer).
            costs: ``[N]`` costs to minimise (J^k of Eq. 8 restricted to layers <= k).
            group_ids: ``[N]`` task ids; rows with the same id are repeated samples of one task and share a
                baseline (their mean cost). None: one global baseline.
        Returns:
            dict with ``loss``, ``cost_mean``, ``cost_std``, ``approx_kl``, ``clip_fraction``,
            ``adv_std`` (the std used to normalise advantages).
        """
        trees = np.asarray(trees, dtype=np.float32)
        costs = np.asarray(costs, dtype=np.float64)
        if costs.shape != (trees.shape[0],):
            raise ValueError(f"costs must have shape [{trees.shape[0]}], got {costs.shape}")
        layers = range(1, int(upto_layer) + 1)
        adv = -(costs - group_baseline(costs, group_ids))  # maximise -cost
        adv_std = float(adv.std())
        if self.normalize_advantages and adv_std > 1e-8:
            adv = adv / adv_std
        adv_t = torch.as_tensor(adv, dtype=torch.float32)
        with torch.no_grad():
            old_logp = self.log_prob(trees, layers)
        lo, hi = 1.0 - self.clip_eps, 1.0 + self.clip_eps
        loss_v = kl_v = clip_v = 0.0
        epochs_run = skipped = 0
        if self.max_kl is not None:
            before = (copy.deepcopy(self.nets.state_dict()), copy.deepcopy(self.optimizer.state_dict()))
        for _ in range(self.epochs if epochs is None else int(epochs)):
            logp = self.log_prob(trees, layers)
            # A tree's log-probability sums 2^(k+1) - 2 sub-goals x d dims at std 0.05, so one epoch can
            # move it by tens of nats: clamp before exp so that ratio stays finite (such a sample is
            # clipped by the surrogate anyway).
            log_ratio = (logp - old_logp).clamp(-20.0, 20.0)
            ratio = torch.exp(log_ratio)
            with torch.no_grad():
                kl_v = float(((ratio - 1.0) - log_ratio).mean())  # k3 estimator, >= 0
                clip_v = float(((ratio - 1.0).abs() > self.clip_eps).float().mean())
            if self.target_kl is not None and kl_v > 1.5 * self.target_kl:
                break  # the policy moved far enough from the one that sampled these trees
            surrogate = torch.minimum(ratio * adv_t, torch.clamp(ratio, lo, hi) * adv_t)
            loss = -surrogate.mean()
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if self.max_grad_norm is not None:
                nn.utils.clip_grad_norm_(self.nets.parameters(), self.max_grad_norm)
            if not all_finite(p.grad for p in self.nets.parameters()):
                self.optimizer.zero_grad(set_to_none=True)
                skipped += 1
                break  # never let a non-finite step into the weights
            self.optimizer.step()
            loss_v = float(loss.detach())
            epochs_run += 1
        rolled_back = 0.0
        if self.max_kl is not None and epochs_run:
            with torch.no_grad():
                log_ratio = (self.log_prob(trees, layers) - old_logp).clamp(-20.0, 20.0)
                final_kl = float(((torch.exp(log_ratio) - 1.0) - log_ratio).mean())
            if not final_kl <= self.max_kl:
                # A trust-region step that left the region: undo it (weights and Adam's moments), as a
                # line search would. Without this the tree-level ratio (2^(k+1) - 2 sub-goals x d dims at
                # std 0.05) let one update move the policy so far that the next ones escalated: KL 0.2 ->
                # 2 -> 14 -> 1e6 within 8 phases and every sub-goal of a layer on the border.
                self.nets.load_state_dict(before[0])
                self.optimizer.load_state_dict(before[1])
                rolled_back = 1.0
        return {
            "loss": loss_v,
            "cost_mean": float(costs.mean()),
            "cost_std": float(costs.std()),
            "approx_kl": kl_v,
            "clip_fraction": clip_v,
            "adv_std": adv_std,
            "epochs_run": float(epochs_run),
            "nonfinite_skipped": float(skipped),
            "rolled_back": rolled_back,
        }


def _wrap_t(x: torch.Tensor) -> torch.Tensor:
    """Angles (differences) into [-pi, pi)."""
    return torch.remainder(x + math.pi, 2 * math.pi) - math.pi


def _check_planner_args(goal_dim, low, high, noise, clip_eps, epochs, target_kl, max_kl) -> None:
    """SubgoalPlanner's argument checks: a ValueError naming the argument and its value."""
    if int(goal_dim) < 1:
        raise ValueError(f"goal_dim must be >= 1, got goal_dim={goal_dim!r}")
    if (low is None) != (high is None):
        raise ValueError("give both low and high goal bounds, or neither")
    if noise not in NOISE_MODES:
        raise ValueError(f"noise must be one of {NOISE_MODES}, got noise={noise!r}")
    if not 0 < clip_eps < 1:
        raise ValueError(f"clip_eps must lie in (0, 1), got clip_eps={clip_eps!r}")
    if int(epochs) < 1:
        raise ValueError(f"epochs must be >= 1, got epochs={epochs!r}")
    for name, value in (("target_kl", target_kl), ("max_kl", max_kl)):
        if value is not None and not float(value) > 0:
            raise ValueError(f"{name} must be > 0 or None, got {name}={value!r}")


def _bounds(low, high, goal_dim: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The goal box as float32 arrays of `goal_dim` (None, None: unbounded)."""
    if low is None:
        return None, None
    low = np.broadcast_to(np.asarray(low, dtype=np.float32), (goal_dim,)).copy()
    high = np.broadcast_to(np.asarray(high, dtype=np.float32), (goal_dim,)).copy()
    if not np.all(high > low):
        raise ValueError(f"goal bounds need high > low, got low={low}, high={high}")
    return low, high
