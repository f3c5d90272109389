"""The goal-conditioned SAC family's sweep trials (the registry's third entry; imports Ray Tune).

`GoalSACTrial` is GoalSAC (SAC or HER, by its config) as a one-seed trial (see SpecTrial).

`SeedStackTrial` trains several seeds of one configuration in one Tune trial (a spec's `seeds_per_trial`,
for the algorithms whose settings say SEED_STACK), their env steps in one loop
(`algorithms.sac.seed_stack.SeedStack`): one batched act for all seeds at every env step and their SAC
updates as one stacked update (`algorithms.sac.stacked_updates`), on every device.

The trial's Tune config is a one-seed trial's with `_seeds: [s0, s1, ...]` in place of `seed`. It builds
the algorithm's own trial class once per seed (its config with `seed: s`, its files under `seed_<s>/`),
so each seed plans, traverses, evaluates and checkpoints exactly as a one-seed trial does; each
iteration runs every seed's iteration in one loop (`algorithms.sac.seed_stack.SeedStack`: the seeds'
env steps together, each drawing from its own generators), then each seed's `train()` for its result.
A stacked seed trains as its one-seed trial (tested).

What it reports (`step`):
* `keys.SEED_RESULTS`: {seed: that seed's metrics, as a one-seed trial logs them} (the MLflow callback
  writes each seed as its own run), and `keys.SEED_ERRORS`: {seed: error} for seeds that failed;
* at the top level, what a searcher or scheduler reads: the mean over the seeds still alive of every
  metric, except the env steps, which are the fewest of any seed still running (a stop criterion on env
  steps ends the trial once every seed reached it).

A seed whose iteration raises (a non-finite planner, a crashed env) stops alone: its error is kept, its
run ends FAILED, the others go on; the trial fails only when every seed has. A seed that reached the
spec's stop criterion does not train further while the others catch up.
"""

from __future__ import annotations

import logging
import math
import pickle
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import ray
from ray import tune

from copilot_ray import keys
from copilot_ray.algorithms.sac.algorithm import GoalSAC
from copilot_ray.algorithms.sac.seed_stack import SeedStack
from copilot_ray.registry import get_algorithm
from copilot_ray.sweep_spec import tune_stop
from copilot_ray.tracking import result_metrics
from copilot_ray.trials.description import load_spec_cached, seed_config
from copilot_ray.trials.planning_trial import nested
from copilot_ray.trials.spec_trial import SpecTrial

logger = logging.getLogger(__name__)
_STATE_FILE = "seed_stack.pkl"


class GoalSACTrial(SpecTrial, GoalSAC):
    """GoalSAC (SAC or HER, by its config) as a sweep trial (see SpecTrial)."""


def _seed_dir(base: str | Path, seed: int) -> Path:
    return Path(base) / f"seed_{seed}"


def _move_logdir(algo, logdir: Path) -> None:
    """Points a seed's algorithm at its own folder of the trial's (its trees go there), dropping the
    empty temporary folder a Trainable built outside Tune makes for itself."""
    made = Path(algo.logdir)
    algo._logdir = str(logdir)  # noqa: SLF001 - Trainable has no other way to set it outside Tune
    if made != logdir and made.is_dir() and not any(made.iterdir()):
        made.rmdir()


_COUNTERS = ("_iteration", "_time_total", "_timesteps_total", "_episodes_total")


def _reached(metrics: Mapping[str, float], stop: Mapping[str, int]) -> bool:
    """Whether a seed's metrics meet any of the stop criteria (Tune's rule: either one ends a trial)."""
    return any(metrics.get(key, -math.inf) >= value for key, value in stop.items())


class SeedStackTrial(tune.Trainable):
    """Several seeds of one configuration in one trial (module docstring)."""

    @classmethod
    def default_resource_request(cls, config):
        """One seed's request: every seed steps in this trial's process (num_env_runners 0)."""
        spec = load_spec_cached(str(config[keys.SPEC_PATH_KEY]))
        trial_class = get_algorithm(spec.algorithm).trial_class()
        return trial_class.default_resource_request(seed_config(config, config[keys.SEEDS_KEY][0]))

    def setup(self, config: dict[str, Any]) -> None:
        spec = load_spec_cached(str(config[keys.SPEC_PATH_KEY]))
        trial_class = get_algorithm(spec.algorithm).trial_class()
        self.seeds = [int(s) for s in config[keys.SEEDS_KEY]]
        self.stop_at = tune_stop(spec)
        self.algos = []
        for seed in self.seeds:
            logdir = _seed_dir(self.logdir, seed)
            logdir.mkdir(parents=True, exist_ok=True)
            algo = trial_class(config=seed_config(config, seed))
            _move_logdir(algo, logdir)
            self.algos.append(algo)
        self.stack = SeedStack(self.algos)
        self.metrics: dict[int, dict[str, float]] = {}  # seed index -> its last metrics (no NaN)
        # Every metric a seed has reported, NaN ones included: a one-seed trial reports its evaluation
        # figures as NaN before its first evaluation so that Tune's strict metric check (a scheduler's
        # metric) finds them in every result; the stack's result must too.
        self.reported: set[str] = set()
        self.errors: dict[int, str] = {}  # seed index -> why it stopped
        self.finished: set[int] = set()  # seed indices that reached the stop criterion

    def step(self) -> dict[str, Any]:
        running = [i for i in range(len(self.seeds)) if i not in self.errors and i not in self.finished]
        failed = self.stack.run_iteration(running)
        for i in running:
            error = failed.get(i)
            if error is None:
                try:
                    result = self.algos[i].train()
                except Exception as err:  # noqa: BLE001 - a seed's failure is its own
                    error = err
            if error is not None:
                self.errors[i] = f"{type(error).__name__}: {error}"
                logger.error("seed %d stopped: %s", self.seeds[i], self.errors[i], exc_info=error)
                continue
            reported = result_metrics(result, rllib_timers=True, keep_nan=True)
            self.reported.update(reported)
            self.metrics[i] = {k: v for k, v in reported.items() if not math.isnan(v)}
            if _reached(self.metrics[i], self.stop_at):
                self.finished.add(i)
        if len(self.errors) == len(self.seeds):
            raise RuntimeError(
                "every seed of the stack failed: "
                + "; ".join(f"seed {self.seeds[i]}: {e}" for i, e in sorted(self.errors.items()))
            )
        return self._result()

    def _result(self) -> dict[str, Any]:
        alive = [i for i in self.metrics if i not in self.errors]
        keys_seen = self.reported | {k for i in alive for k in self.metrics[i]}
        mean = {}
        for k in sorted(keys_seen - {keys.TRAINING_ITERATION, keys.TIME_TOTAL_S}):
            values = [self.metrics[i][k] for i in alive if k in self.metrics[i]]
            # NaN where no live seed has measured it yet, as a one-seed trial reports it
            mean[k] = sum(values) / len(values) if values else math.nan
        still = [i for i in alive if i not in self.finished] or alive
        mean[keys.ENV_STEPS] = min(self.metrics[i].get(keys.ENV_STEPS, 0.0) for i in still)
        result = nested(mean)
        result[keys.SEED_RESULTS] = {str(self.seeds[i]): dict(self.metrics[i]) for i in sorted(self.metrics)}
        result[keys.SEED_ERRORS] = {str(self.seeds[i]): e for i, e in sorted(self.errors.items())}
        if ray.is_initialized():
            result[keys.NODE_ID] = ray.get_runtime_context().get_node_id()
        result["done"] = len(self.finished) + len(self.errors) == len(self.seeds)
        return result

    # ------------------------------------------------------------------ checkpoints
    def save_checkpoint(self, checkpoint_dir: str) -> None:
        """Every seed's algorithm in `seed_<s>/`, and the stack's state (its weights and optimizer
        state, the seeds' last metrics and errors).

        A seed's folder alone is not that seed's whole state: its optimizer's moments are in the
        stack's file (its learner's are never stepped). A stack restores from the whole
        checkpoint; its seeds' folders are what MLflow keeps of each run for reading its weights."""
        for seed, algo in zip(self.seeds, self.algos, strict=True):
            algo.save_checkpoint(str(_seed_dir(checkpoint_dir, seed)))
        state = {
            "seeds": self.seeds,
            "stack": self.stack.get_state(),
            "metrics": self.metrics,
            "reported": sorted(self.reported),
            "errors": self.errors,
            "finished": sorted(self.finished),
            # what `Trainable.restore` would restore of each seed's own counters (its iteration comes
            # back with RLlib's state, its wall time would restart at 0)
            "counters": [{name: getattr(algo, name) for name in _COUNTERS} for algo in self.algos],
        }
        with open(Path(checkpoint_dir) / _STATE_FILE, "wb") as f:
            pickle.dump(state, f)

    def load_checkpoint(self, checkpoint_dir: str) -> None:
        with open(Path(checkpoint_dir) / _STATE_FILE, "rb") as f:
            state = pickle.load(f)
        if state["seeds"] != self.seeds:
            raise ValueError(
                f"a checkpoint of seeds {state['seeds']} cannot restore a stack of seeds {self.seeds}"
            )
        for seed, algo in zip(self.seeds, self.algos, strict=True):
            algo.load_checkpoint(str(_seed_dir(checkpoint_dir, seed)))
        for algo, counters in zip(self.algos, state.get("counters") or (), strict=False):
            for name, value in counters.items():
                setattr(algo, name, value)
        self.stack.set_state(state["stack"])  # after the algorithms: the stack's weights are the live ones
        self.metrics = dict(state["metrics"])
        self.reported = set(state.get("reported", ()))
        self.errors = dict(state["errors"])
        self.finished = set(state["finished"])

    def cleanup(self) -> None:
        """Stops every seed's algorithm, each even if another's stop raises (the first error is raised
        once all have stopped)."""
        failed = None
        for algo in self.algos:
            try:
                algo.stop()
            except Exception as err:  # noqa: BLE001 - the other seeds' env runners must still stop
                failed = failed or err
        self.stack = None
        if failed is not None:
            raise failed
