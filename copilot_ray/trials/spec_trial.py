"""SpecTrial: what makes an RLlib Algorithm a sweep trial (Ray imported here). A registered algorithm's
trial is ``class MyTrial(SpecTrial, MyAlgorithm)``, in a `trial.py` beside the algorithm."""

from __future__ import annotations

import math
from typing import Any

import ray

from copilot_ray.keys import (
    EVAL_FRESH,
    EVAL_RETURN,
    EVAL_SUCCESS_AUC,
    NODE_ID,
    PRIVILEGE_COUNTS,
    SPEC_PATH_KEY,
    SUCCESS_METRICS,
    result_value,
    validation_metrics,
)
from copilot_ray.trials.description import algorithm_config

_LAST_EVAL_STATE = "copilot_trial_last_eval"


class SpecTrial:
    """Mixin that makes an RLlib Algorithm a sweep trial: built from a flat Tune config
    ``{dotted params..., "seed": s, "_spec_path": p}``. A registered algorithm's trial class is
    ``class MyTrial(SpecTrial, MyAlgorithm)`` (the registry's third entry).

    ``__init__`` and ``default_resource_request`` turn the flat dict into the RLlib config with
    ``build_algorithm_config(flat, spec)`` (spec loaded from ``_spec_path``), so Tune's placement
    group fits the env runners and RLlib's checkpointing is untouched.

    Every result carries the trial's ``eval_metrics`` (``copilot/eval/success`` and
    ``success_planned`` / ``success_direct`` where the algorithm has them), their area under the curve
    and the validation twins of all of them (Tune's strict metric check and Optuna need the searched
    metric in every result): iterations without an evaluation repeat the last evaluated value (NaN before
    the first one) and set ``copilot/eval/fresh`` to 0 (1 when evaluated now). The analysis reads fresh
    evaluations only. The privilege counts (``keys.PRIVILEGE_COUNTS``) are 0 where an algorithm logs none.
    """

    eval_metrics: tuple[str, ...] = (*SUCCESS_METRICS, EVAL_RETURN)

    def __init__(self, config=None, **kwargs):
        if isinstance(config, dict) and SPEC_PATH_KEY in config:
            config = algorithm_config(config)
        self._last_eval: dict[str, float] = {}
        super().__init__(config=config, **kwargs)

    @classmethod
    def default_resource_request(cls, config):
        if isinstance(config, dict) and SPEC_PATH_KEY in config:
            config = algorithm_config(config)
        return super().default_resource_request(config)

    def step(self):
        result = super().step()
        tested = (*self.eval_metrics, EVAL_SUCCESS_AUC)
        carried = (*tested, *validation_metrics(*tested))
        # RLlib reports a window-1 stat logged in an earlier iteration as NaN: not an evaluation.
        fresh = all(_is_number(result_value(result, key)) for key in self.eval_metrics)
        for key in carried:
            value = result_value(result, key)
            if fresh and _is_number(value):
                self._last_eval[key] = float(value)
            else:
                _set_nested(result, key, self._last_eval.get(key, float("nan")))
        _set_nested(result, EVAL_FRESH, 1.0 if fresh else 0.0)
        for key in PRIVILEGE_COUNTS:
            if not _is_number(result_value(result, key)):
                _set_nested(result, key, 0.0)
        if ray.is_initialized():  # (a trial built outside Tune, as a stacked seed's, starts no Ray)
            result[NODE_ID] = ray.get_runtime_context().get_node_id()
        return result

    def get_state(self, *args, **kwargs):
        state = super().get_state(*args, **kwargs)
        state[_LAST_EVAL_STATE] = dict(getattr(self, "_last_eval", {}))
        return state

    def set_state(self, state):
        super().set_state(state)
        self._last_eval = dict(state.get(_LAST_EVAL_STATE, {}))


def _set_nested(result: dict, key: str, value: Any) -> None:
    """``result[a][b][c] = value`` for key ``a/b/c`` (the shape RLlib's results have)."""
    *parents, leaf = key.split("/")
    node = result
    for part in parents:
        node = node.setdefault(part, {})
    node[leaf] = value


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and not math.isnan(v)


# ================================================================================================ callbacks
