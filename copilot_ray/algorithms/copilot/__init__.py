"""CO-PILOT as an RLlib Algorithm: config, algorithm, traversal env.

`CoPilot` and `CoPilotConfig` are loaded on first access (PEP 562): `copilot_ray.evaluation` needs the
traversal env's helpers, and the algorithm needs the evaluation, so an eager import here would make
`import copilot_ray.evaluation` on its own a circular import.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from copilot_ray.algorithms.copilot.algorithm import CoPilot
    from copilot_ray.algorithms.copilot.config import CoPilotConfig

__all__ = ["CoPilot", "CoPilotConfig"]

_HOMES = {"CoPilot": "algorithm", "CoPilotConfig": "config"}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
