"""SGTPGConfig: what one SGT-PG trial runs (no Ray)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from copilot_ray.algorithms.sgt_pg.settings import SETTINGS


def _planner_defaults() -> dict[str, Any]:
    return {s.field: s.default for s in SETTINGS.values() if s.target == "planner"}


@dataclass(frozen=True)
class SGTPGConfig:
    env_id: str
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    tree_depth: int = SETTINGS["tree_depth"].default
    task_batch_size: int = SETTINGS["task_batch_size"].default
    phases_per_iteration: int = SETTINGS["phases_per_iteration"].default
    collision_penalty: float = SETTINGS["collision_penalty"].default
    eval_num_tasks: int = SETTINGS["eval_num_tasks"].default
    rrt_reference_time_s: float = SETTINGS["rrt_reference_time_s"].default
    planner: Mapping[str, Any] = field(default_factory=_planner_defaults)  # pi_p's settings by field

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: Any) -> SGTPGConfig:
        """Flat setting values (checked by the spec; ``planner.<field>`` keys) + a registry RunContext."""
        planner = _planner_defaults()
        given: dict[str, Any] = {}
        for key, setting in SETTINGS.items():
            if key not in values:
                continue
            if setting.target == "planner":
                planner[setting.field] = values[key]
            else:
                given[key] = values[key]
        return cls(
            env_id=run.env_id, env_config=dict(run.env_config), seed=int(run.seed), planner=planner, **given
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
