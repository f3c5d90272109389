"""HIRO's sub-goal maths in goal-space (achieved-goal) coordinates, numpy only: the offset bounds, the
goal transition h, the low level's reward and the off-policy correction's candidate choice.

Kept apart from the learners and the env loop so that each rule can be checked on constructed cases.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

# (flat low-level inputs [M, D], actions [M, A]) -> log pi_low(a | input) [M]
LogProb = Callable[[np.ndarray, np.ndarray], np.ndarray]
# (observations [..., o], absolute sub-goals [..., g], achieved goals [..., g]) -> flat inputs [..., D]
Compose = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def goal_transition(achieved: np.ndarray, offset: np.ndarray, next_achieved: np.ndarray) -> np.ndarray:
    """h(s, g, s') = s + g - s': the offset that keeps the absolute sub-goal s + g where it was."""
    return achieved + offset - next_achieved


def dense_low_reward(achieved: np.ndarray, offset: np.ndarray, next_achieved: np.ndarray) -> np.ndarray:
    """HIRO's intrinsic reward -||s + g - s'||_2 (Euclidean in goal coordinates; angles not wrapped)."""
    return -np.linalg.norm(achieved + offset - next_achieved, axis=-1)


@dataclass(frozen=True)
class SubgoalBox:
    """The high level's action space: offsets in [-bound, bound] per goal dimension, where
    bound = subgoal_range x (goal_high - goal_low); its SAC acts in [-1, 1] and is scaled by bound."""

    bound: np.ndarray  # [g] > 0

    @classmethod
    def from_goal_space(cls, low: np.ndarray, high: np.ndarray, subgoal_range: float) -> SubgoalBox:
        width = np.asarray(high, np.float64) - np.asarray(low, np.float64)
        if not (np.isfinite(width).all() and (width > 0).all()):
            raise ValueError(
                f"hrl.subgoal_range is a fraction of the goal space's width, which needs finite bounds; "
                f"goal space low={np.asarray(low).tolist()} high={np.asarray(high).tolist()}"
            )
        return cls((float(subgoal_range) * width).astype(np.float32))

    def offset(self, action: np.ndarray) -> np.ndarray:
        """High-level action in [-1, 1] -> offset in goal units."""
        return (np.clip(action, -1.0, 1.0) * self.bound).astype(np.float32)

    def action(self, offset: np.ndarray) -> np.ndarray:
        """Offset in goal units -> high-level action in [-1, 1] (clipped)."""
        return np.clip(offset / self.bound, -1.0, 1.0).astype(np.float32)


def correction_candidates(
    stored: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    box: SubgoalBox,
    num_samples: int,
    rng: np.random.Generator,
) -> np.ndarray:
    """[B, 2 + num_samples, g] offsets: the stored one, end - start, and `num_samples` draws from
    N(end - start, (bound / 2)^2) (HIRO's), all clipped to the box."""
    diff = end - start
    noise = rng.normal(0.0, 0.5, size=(len(diff), int(num_samples), diff.shape[-1])) * box.bound
    cands = np.concatenate([stored[:, None], diff[:, None], diff[:, None] + noise], axis=1)
    return np.clip(cands, -box.bound, box.bound).astype(np.float32)


def choose_candidates(
    candidates: np.ndarray,
    start: np.ndarray,
    observations: np.ndarray,
    achieved: np.ndarray,
    actions: np.ndarray,
    mask: np.ndarray,
    log_prob: LogProb,
    compose: Compose,
) -> np.ndarray:
    """Index [B] of the candidate offset under which the current low level most likely took the stored
    actions: argmax_k sum_j mask_j log pi_low(a_j | o_j, start + g_k, achieved_j).

    Shapes: candidates [B, K, g]; start [B, g] (achieved goal where the segment began); observations
    [B, c, o], achieved [B, c, g], actions [B, c, A], mask [B, c] (False past a short segment's end).
    Under h the absolute sub-goal start + g_k is the same at every step j of the segment. Ties go to
    the lower index (the stored offset first)."""
    b, k, _ = candidates.shape
    c = observations.shape[1]
    targets = np.broadcast_to((start[:, None] + candidates)[:, :, None], (b, k, c, candidates.shape[-1]))
    obs = np.broadcast_to(observations[:, None], (b, k, *observations.shape[1:]))
    ach = np.broadcast_to(achieved[:, None], (b, k, *achieved.shape[1:]))
    act = np.broadcast_to(actions[:, None], (b, k, *actions.shape[1:]))
    flat = compose(obs, targets, ach).reshape(b * k * c, -1)
    lp = np.asarray(log_prob(flat, act.reshape(b * k * c, -1)), np.float64).reshape(b, k, c)
    scores = np.where(mask[:, None, :], lp, 0.0).sum(axis=-1)
    return np.argmax(scores, axis=1)
