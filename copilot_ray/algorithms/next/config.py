"""NEXTConfig: what one NEXT trial runs (no Ray)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from copilot_ray.algorithms.next.settings import SETTINGS

_SEARCH_FIELDS = {  # SearchSettings field -> setting key
    "step": "step_length",
    "max_iterations": "max_iterations",
    "max_checks": "max_checks",
    "improve_iterations": "improve_iterations",
    "exploration": "exploration",
    "uniform_share": "uniform_share",
    "goal_bias": "goal_bias",
    "candidates": "candidates",
    "policy_std": "policy_std",
    "rewire_factor": "rewire_factor",
}


@dataclass(frozen=True)
class NEXTConfig:
    env_id: str
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    step_length: float = SETTINGS["step_length"].default
    max_iterations: int = SETTINGS["max_iterations"].default
    max_checks: int = SETTINGS["max_checks"].default
    improve_iterations: int = SETTINGS["improve_iterations"].default
    exploration: float = SETTINGS["exploration"].default
    uniform_share: float = SETTINGS["uniform_share"].default
    goal_bias: float = SETTINGS["goal_bias"].default
    candidates: int = SETTINGS["candidates"].default
    policy_std: float = SETTINGS["policy_std"].default
    rewire_factor: float = SETTINGS["rewire_factor"].default
    hidden: list[int] = field(default_factory=lambda: list(SETTINGS["hidden"].default))
    lr: float = SETTINGS["lr"].default
    batch_size: int = SETTINGS["batch_size"].default
    hindsight: bool = SETTINGS["hindsight"].default
    demonstrator: str = SETTINGS["demonstrator"].default
    num_demos: int = SETTINGS["num_demos"].default
    demo_time_s: float = SETTINGS["demo_time_s"].default
    demo_train_steps: int = SETTINGS["demo_train_steps"].default
    self_improve_rounds: int = SETTINGS["self_improve_rounds"].default
    tasks_per_round: int = SETTINGS["tasks_per_round"].default
    round_train_steps: int = SETTINGS["round_train_steps"].default
    train_improve_iterations: int = SETTINGS["train_improve_iterations"].default
    eval_num_tasks: int = SETTINGS["eval_num_tasks"].default
    rrt_reference_time_s: float = SETTINGS["rrt_reference_time_s"].default

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: Any) -> NEXTConfig:
        """Flat setting values (checked by the spec) + a registry RunContext."""
        given = {key: values[key] for key in SETTINGS if key in values}
        return cls(env_id=run.env_id, env_config=dict(run.env_config), seed=int(run.seed), **given)

    def search_settings(self):
        """The planner's SearchSettings (copilot_ray.planning.next_planner)."""
        from copilot_ray.planning.next_planner import SearchSettings

        return SearchSettings(**{name: getattr(self, key) for name, key in _SEARCH_FIELDS.items()})

    def train_settings(self):
        """The planner's TrainSettings (copilot_ray.planning.next_planner)."""
        from copilot_ray.planning.next_planner import TrainSettings

        return TrainSettings(
            hidden=tuple(int(h) for h in self.hidden),
            lr=float(self.lr),
            batch_size=int(self.batch_size),
            hindsight=bool(self.hindsight),
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
