"""The sweep trial of a planner-only algorithm (RRT*, SGT-PG, NEXT): a plain Ray Tune Trainable, no RLlib.

These algorithms take no environment steps: they query the env's collision checks. Each result reports
the checks spent so far as ``env_runners/num_env_steps_sampled_lifetime`` (the x axis of every curve,
MLflow's step and the sweep's ``stop.env_steps``), so that they are drawn against "interaction steps" as
in the paper's Fig. 4, where a planner's interactions are its collision checks. ``paths/collision_checks``
carries the same number under its own name.

A subclass implements ``start(cfg, env)``, ``iterate() -> (metrics, collision_checks, done)``,
``state() -> dict`` and ``restore_state(state)`` (not ``restore``: Tune calls that one with a checkpoint when it retries or resumes a trial); this class turns the trial's flat Tune config into the
algorithm's config (``copilot_ray.sweep_spec.build_algorithm_config``), builds the env, nests the metrics the
way an RLlib result nests them, and checkpoints ``state()`` with pickle. Outside a sweep, give it the
config itself: ``RRTStarTrial(config={"algorithm_config": RRTStarConfig.from_settings(values, run)})``.
"""

from __future__ import annotations

import pickle
from abc import ABC, abstractmethod
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import ray
from ray import tune

from copilot_ray import keys
from copilot_ray.envs import make
from copilot_ray.trials.description import algorithm_config


def nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    """``{"a/b": 1}`` -> ``{"a": {"b": 1}}`` (how RLlib results nest metric keys)."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        node = out
        *parents, leaf = keys.metric_path(key)
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    return out


def config_from_trial(config: Mapping[str, Any]) -> Any:
    """The algorithm config: built from a sweep trial's flat Tune config, or given as `algorithm_config`."""
    return algorithm_config(config) if keys.SPEC_PATH_KEY in config else config["algorithm_config"]


class PickledStateTrial(tune.Trainable, ABC):
    """A Tune Trainable without RLlib whose checkpoint is its `state()`, pickled (the planner baselines'
    trials and HRL's); its results say which node ran them."""

    STATE_FILE = "trial_state.pkl"

    def save_checkpoint(self, checkpoint_dir: str) -> None:
        with open(Path(checkpoint_dir) / self.STATE_FILE, "wb") as f:
            pickle.dump(self.state(), f)

    def load_checkpoint(self, checkpoint: str | dict) -> None:
        with open(Path(checkpoint) / self.STATE_FILE, "rb") as f:
            self.restore_state(pickle.load(f))  # noqa: S301 - our own checkpoint

    @staticmethod
    def with_node_id(result: dict) -> dict:
        if ray.is_initialized():  # (asking for the context outside Ray would start one)
            result[keys.NODE_ID] = ray.get_runtime_context().get_node_id()
        return result

    @abstractmethod
    def state(self) -> dict:
        """Everything ``restore_state`` needs to continue exactly (picklable)."""

    @abstractmethod
    def restore_state(self, state: dict) -> None:
        """Continue from a ``state()``."""


class PlanningTrial(PickledStateTrial):
    """Base of RRTStarTrial, SGTPGTrial and NEXTTrial (see the module docstring)."""

    STATE_FILE = "planner_trial_state.pkl"

    def setup(self, config: dict) -> None:
        self.cfg = config_from_trial(config)
        self.env = make(self.cfg.env_id, **dict(self.cfg.env_config))
        self.start(self.cfg, self.env)

    def step(self) -> dict:
        metrics, checks, done = self.iterate()
        privileges = {
            keys.PRIVILEGE_COLLISION_CHECKS: float(checks),
            keys.PRIVILEGE_RESETS: 0.0,
            keys.PRIVILEGE_MAP_QUERIES: 0.0,
        }
        result = nested(
            {**metrics, **privileges, keys.PATH_COLLISION_CHECKS: float(checks), keys.ENV_STEPS: int(checks)}
        )
        if done:
            result["done"] = True
        return self.with_node_id(result)

    def cleanup(self) -> None:
        self.env.close()

    # ------------------------------------------------------------------ what a subclass provides
    @abstractmethod
    def start(self, cfg: Any, env: Any) -> None:
        """Set up the run from the algorithm's config and the built env."""

    @abstractmethod
    def iterate(self) -> tuple[dict[str, float], int, bool]:
        """One iteration: (``paths/*`` metrics, collision checks so far, done)."""
