"""SAC's three losses for one batch, as one pure function over tensors.

Shared by the learner's RLlib path (`GCSACTorchLearner.compute_losses`) and the fused step
(`sac_step.SACStep`), so both optimise exactly the same objective:

    critic:      mean(huber(Q_i(s, a), y)) per critic (or 0.5 * MSE), y = `bellman_target`
    actor:       mean(alpha * log pi(a~|s) - min_i Q_i(s, a~)),   a~ ~ pi(.|s) reparameterised
    temperature: -mean(log_alpha * (log pi(a~|s) + target_entropy))

Each loss reaches only its own parameters (the module's forward gives `q_curr` with the critics
frozen; targets and alpha are detached where they enter another loss), so their sum can be
back-propagated once.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.algorithms.sac.sac_learner import (
    LOGPS_KEY,
    QF_LOSS_KEY,
    QF_MAX_KEY,
    QF_MEAN_KEY,
    QF_MIN_KEY,
    QF_PREDS,
    QF_TWIN_LOSS_KEY,
    QF_TWIN_PREDS,
    TD_ERROR_MEAN_KEY,
)
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.learner import POLICY_LOSS_KEY

CRITIC_LOSSES = ("huber", "mse")


def bellman_target(
    rewards: torch.Tensor,
    terminateds: torch.Tensor,
    q_target_next: torch.Tensor,
    logp_next: torch.Tensor,
    alpha: torch.Tensor,
    gamma: float,
    n_step: torch.Tensor | None = None,
) -> torch.Tensor:
    """y = r + gamma^n * (1 - terminated) * (min_i Q'_i(s', a') - alpha * log pi(a'|s')), detached."""
    discount = gamma if n_step is None else gamma ** n_step.float()
    v_next = q_target_next - alpha.detach() * logp_next
    return (rewards.float() + discount * (1.0 - terminateds.float()) * v_next).detach()


def sac_losses(
    fwd_out: dict[str, Any],
    batch: dict[str, Any],
    log_alpha: torch.Tensor,
    target_entropy: torch.Tensor | float,
    *,
    gamma: float,
    critic_loss: str,
    twin_q: bool,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """(actor + critic(s) + temperature loss, the statistics RLlib's SAC learner logs, detached).

    `fwd_out` is `GCSACTorchRLModule.forward_train`'s output for `batch`; `weights` and `n_step`
    columns are optional (ones when absent)."""
    alpha = torch.exp(log_alpha)
    target = bellman_target(
        batch[Columns.REWARDS],
        batch[Columns.TERMINATEDS],
        fwd_out["q_target_next"],
        fwd_out["logp_next_resampled"],
        alpha,
        gamma,
        batch.get("n_step"),
    )
    weights = batch.get("weights")

    def critic_loss_of(q):
        if critic_loss == "mse":
            per_item = 0.5 * (q - target) ** 2
        else:
            per_item = torch.nn.functional.huber_loss(q, target, reduction="none", delta=1.0)
        return torch.mean(per_item if weights is None else weights * per_item)

    q1 = fwd_out[QF_PREDS]
    loss_q1 = critic_loss_of(q1)
    total_critic = loss_q1
    td_error = torch.abs(q1 - target)
    if twin_q:
        q2 = fwd_out[QF_TWIN_PREDS]
        loss_q2 = critic_loss_of(q2)
        total_critic = loss_q1 + loss_q2
        td_error = 0.5 * (td_error + torch.abs(q2 - target))

    logp = fwd_out["logp_resampled"]
    actor_loss = torch.mean(alpha.detach() * logp - fwd_out["q_curr"])
    alpha_loss = -torch.mean(log_alpha * (logp.detach() + target_entropy))

    with torch.no_grad():
        q_curr = fwd_out["q_curr"]
        stats = {
            POLICY_LOSS_KEY: actor_loss,
            QF_LOSS_KEY: loss_q1,
            "alpha_loss": alpha_loss,
            "alpha_value": alpha[0],
            "log_alpha_value": log_alpha[0],
            "target_entropy": torch.as_tensor(target_entropy),
            LOGPS_KEY: torch.mean(logp),
            QF_MEAN_KEY: torch.mean(q_curr),
            QF_MAX_KEY: torch.max(q_curr),
            QF_MIN_KEY: torch.min(q_curr),
            TD_ERROR_MEAN_KEY: torch.mean(td_error),
        }
        if twin_q:
            stats[QF_TWIN_LOSS_KEY] = loss_q2
        stats = {k: v.detach() for k, v in stats.items()}
    return actor_loss + total_critic + alpha_loss, stats
