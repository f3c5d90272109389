"""A cheap guard shared by the SAC learner and the planner: are all gradients finite?"""

from __future__ import annotations

from collections.abc import Iterable

import torch


def all_finite(grads: Iterable[torch.Tensor | None]) -> bool:
    """One fused norm per tensor and a single host sync, instead of one `isfinite` check per tensor."""
    grads = [g for g in grads if g is not None]
    if not grads:
        return True
    return bool(torch.isfinite(torch.stack(torch._foreach_norm(grads))).all())
