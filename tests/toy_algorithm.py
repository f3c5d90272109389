"""A toy algorithm for tests: what a new algorithm (a baseline) adds, in one module.

Registered with one line, `register_algorithm("toy-ppo", "tests.toy_algorithm",
"tests.toy_algorithm:ToyPPOConfig", "tests.toy_algorithm:ToyPPOTrial")`: this module is its settings
module, its config module and its sweep trial's.
(A real one keeps RLlib out of its settings module, so that specs are checked without Ray.)
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ray.rllib.algorithms.ppo import PPO, PPOConfig

from copilot_ray.settings import float_setting, int_setting
from copilot_ray.trials.spec_trial import SpecTrial

SETTINGS = {
    s.key: s
    for s in (
        float_setting("lr", "training", 5e-4, "PPO's learning rate", 0.0, lo_open=True),
        int_setting("num_epochs", "training", 2, "PPO epochs per batch", 1),
    )
}
METRICS = ("env_runners/episode_return_mean",)


class ToyPPOConfig(PPOConfig):
    @classmethod
    def from_settings(cls, values: Mapping[str, Any], run: Any) -> ToyPPOConfig:
        training = {key: values.get(key, s.default) for key, s in SETTINGS.items()}
        config = cls().environment(run.env_id, env_config=dict(run.env_config)).debugging(seed=run.seed)
        return config.training(**training)


class ToyPPOTrial(SpecTrial, PPO):
    """What a sweep runs for `algorithm: toy-ppo`."""
