"""HRLConfig: what one HRL trial runs (no Ray; the registry's config class)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from copilot_ray.algorithms.hrl.settings import LEVELS, SETTINGS, combination_problems


def _level_defaults(level: str) -> dict[str, Any]:
    return {s.field: s.default for s in SETTINGS.values() if s.target == level}


@dataclass(frozen=True)
class HRLConfig:
    """Flat settings, except each level's SAC settings (`low`, `high`: `{field: value}`).

    `hrl.c` is the field `hrl_c` (and so on for `hrl.*`). Every value is checked against its setting
    on construction; a bad one raises ValueError naming the key and the value.
    """

    env_id: str
    env_config: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0
    torch_threads: int = 1
    tau_max: int = SETTINGS["tau_max"].default
    task_batch_size: int = SETTINGS["task_batch_size"].default
    reward_scale: float = SETTINGS["reward_scale"].default
    agent_input: str = SETTINGS["agent_input"].default
    eval_interval: int = SETTINGS["eval_interval"].default
    eval_every_env_steps: int = SETTINGS["eval_every_env_steps"].default
    eval_num_tasks: int = SETTINGS["eval_num_tasks"].default
    eval_action: str = SETTINGS["eval_action"].default
    env_steps_per_iteration: int = SETTINGS["env_steps_per_iteration"].default
    num_steps_sampled_before_learning_starts: int = SETTINGS[
        "num_steps_sampled_before_learning_starts"
    ].default
    replay_capacity: int = SETTINGS["replay_capacity"].default
    hrl_c: int = SETTINGS["hrl.c"].default
    hrl_subgoal_range: float = SETTINGS["hrl.subgoal_range"].default
    hrl_low_reward: str = SETTINGS["hrl.low_reward"].default
    hrl_off_policy_correction: bool = SETTINGS["hrl.off_policy_correction"].default
    hrl_num_candidates: int = SETTINGS["hrl.num_candidates"].default
    low: Mapping[str, Any] = field(default_factory=lambda: _level_defaults("low"))
    high: Mapping[str, Any] = field(default_factory=lambda: _level_defaults("high"))

    def __post_init__(self) -> None:
        values = self.setting_values()
        for key, value in values.items():
            if (why := SETTINGS[key].problem(value)) is not None:
                raise ValueError(f"HRLConfig: {key}={value!r} is invalid: {why}")
        for keys_, value, why in combination_problems(values):
            raise ValueError(f"HRLConfig: {', '.join(keys_)}={value!r} is invalid: {why}")
        for level in LEVELS:
            unknown = sorted(set(getattr(self, level)) - set(_level_defaults(level)))
            if unknown:
                raise ValueError(f"HRLConfig: {level}.{unknown[0]} is not a setting")

    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: Any) -> HRLConfig:
        """Flat setting values (dotted keys) + a registry RunContext (env, seed, the process's CPUs)."""
        unknown = sorted(set(values) - set(SETTINGS))
        if unknown:
            raise ValueError(f"HRLConfig: {unknown[0]!r} is not a setting of hrl; known: {sorted(SETTINGS)}")
        levels = {level: _level_defaults(level) for level in LEVELS}
        flat: dict[str, Any] = {}
        for key, value in values.items():
            setting = SETTINGS[key]
            if setting.target in LEVELS:
                levels[setting.target][setting.field] = value
            else:
                flat[key.replace(".", "_")] = value
        return cls(
            env_id=run.env_id,
            env_config=dict(run.env_config),
            seed=int(run.seed),
            torch_threads=max(1, int(getattr(run, "num_cpus_for_main_process", 1) or 1)),
            **flat,
            **levels,
        )

    def setting_values(self) -> dict[str, Any]:
        """`{setting key: value}` of every setting (dotted keys)."""
        out = {}
        for key, setting in SETTINGS.items():
            if setting.target in LEVELS:
                out[key] = getattr(self, setting.target).get(setting.field, setting.default)
            else:
                out[key] = getattr(self, key.replace(".", "_"))
        return out

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
