"""HRLTrial: the hierarchy as a sweep trial, a plain Ray Tune Trainable (the registry's third entry).

RLlib's env runners sample one policy; the two-level sampler runs on the trial's own process instead
(as the planner baselines' trials do, `copilot_ray.algorithms.planning_trial`). Results nest metric keys
the way an RLlib result does, so the sweep's tracking, stop criteria (`env_steps`) and progress lines
read them like any other algorithm's; every result carries the last evaluation's figures with
`copilot/eval/fresh` (0 when repeated), as `SpecTrial` does for the RLlib algorithms. A checkpoint is the
whole state (`HRL.get_state`), so a resumed trial continues its env-step count and its randomness.
Outside a sweep: ``HRLTrial(config={"algorithm_config": HRLConfig.from_settings(values, run)})``.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import ray
from ray import tune

from copilot_ray import keys
from copilot_ray.algorithms.hrl.algorithm import HRL
from copilot_ray.algorithms.planning_trial import config_from_trial, nested

_STATE_FILE = "hrl_state.pkl"


class HRLTrial(tune.Trainable):
    """`HRL.train()` per Tune iteration (see the module docstring)."""

    def setup(self, config: dict) -> None:
        cfg = config_from_trial(config) if keys.SPEC_PATH_KEY in config else config["algorithm_config"]
        self.algo = HRL(cfg)

    def step(self) -> dict:
        result = nested(self.algo.train())
        if ray.is_initialized():  # (asking for the context outside Ray would start one)
            result[keys.NODE_ID] = ray.get_runtime_context().get_node_id()
        return result

    def save_checkpoint(self, checkpoint_dir: str) -> None:
        with open(Path(checkpoint_dir) / _STATE_FILE, "wb") as f:
            pickle.dump(self.algo.get_state(), f)

    def load_checkpoint(self, checkpoint: str | dict) -> None:
        with open(Path(checkpoint) / _STATE_FILE, "rb") as f:
            self.algo.set_state(pickle.load(f))  # noqa: S301 - our own checkpoint

    def cleanup(self) -> None:
        self.algo.stop()
