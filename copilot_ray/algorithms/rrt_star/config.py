"""RRTStarConfig: what one RRT* trial runs (no Ray)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from copilot_ray.algorithms.rrt_star.settings import SETTINGS


@dataclass(frozen=True)
class RRTStarConfig:
    env_id: str
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    time_limit_s: float = SETTINGS["time_limit_s"].default
    eval_num_tasks: int = SETTINGS["eval_num_tasks"].default
    tasks_per_iteration: int = SETTINGS["tasks_per_iteration"].default
    range: float | None = SETTINGS["range"].default

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: Any) -> RRTStarConfig:
        """Flat setting values (checked by the spec) + a registry RunContext."""
        given = {key: values[key] for key in SETTINGS if key in values}
        return cls(env_id=run.env_id, env_config=dict(run.env_config), seed=int(run.seed), **given)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
