"""HRLTrial: the hierarchy as a sweep trial, a plain Ray Tune Trainable (the registry's third entry).

RLlib's env runners sample one policy; the two-level sampler runs on the trial's own process instead
(as the planner baselines' trials do, `copilot_ray.trials.planning_trial`). Results nest metric keys
the way an RLlib result does, so the sweep's tracking, stop criteria (`env_steps`) and progress lines
read them like any other algorithm's; every result carries the last evaluation's figures with
`copilot/eval/fresh` (0 when repeated), as `SpecTrial` does for the RLlib algorithms. A checkpoint is the
whole state (`HRL.get_state`), so a resumed trial continues its env-step count and its randomness.
Outside a sweep: ``HRLTrial(config={"algorithm_config": HRLConfig.from_settings(values, run)})``.
"""

from __future__ import annotations

from copilot_ray.algorithms.hrl.algorithm import HRL
from copilot_ray.trials.planning_trial import PickledStateTrial, config_from_trial, nested


class HRLTrial(PickledStateTrial):
    """`HRL.train()` per Tune iteration (see the module docstring)."""

    STATE_FILE = "hrl_state.pkl"

    def setup(self, config: dict) -> None:
        self.algo = HRL(config_from_trial(config))

    def step(self) -> dict:
        return self.with_node_id(nested(self.algo.train()))

    def state(self) -> dict:
        return self.algo.get_state()

    def restore_state(self, state: dict) -> None:
        self.algo.set_state(state)

    def cleanup(self) -> None:
        self.algo.stop()
