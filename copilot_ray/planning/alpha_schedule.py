"""Schedules of alpha, the weight of the Euclidean term in the segment cost (paper Eq. 11).

The paper gives two readings, and both are expressible here:

(a) Sec. 3.3: "we start from alpha = 1 and gradually reduce it towards 0 during the first two episodes.
    After that, the cost function is the time cost" -> ``preset("paper_warm_start")``: linear 1 -> 0 over
    2 episodes on the GLOBAL clock (alpha = 1, 0.5, then 0 for ever).
(b) Sec. 4.1: "We linearly reduce alpha from 0.9 to 0.1 throughout every episode" ->
    ``preset("paper_per_task")``: linear 0.9 -> 0.1 on the PER-TASK clock, which restarts for every new
    task mini-batch and runs over its b repetitions (b = 5: 0.9, 0.7, 0.5, 0.3, 0.1).

Clock. One CO-PILOT episode is one repetition of Algorithm 3's inner loop on a task mini-batch (one
top-down construction plus one bottom-up traversal). ``value(episode, repetition, repetitions)`` is pure:
``episode`` counts all episodes so far (0-based, the global clock), ``repetition`` is the index of the
current episode within its task mini-batch (0..repetitions-1, the per-task clock). ``AlphaClock`` is the
small mutable counter an algorithm keeps (and checkpoints) and advances once per episode.

Kinds (t is the clock value: ``episode`` for ``clock="global"``, ``repetition`` for ``"per_task"``):

* ``constant``: ``alpha``.
* ``linear``: from ``start`` at t = 0 to ``end`` at t = ``duration``, then ``end``. With the per-task
  clock ``duration`` may be omitted and means ``repetitions - 1`` (start at the first repetition, end at
  the last one).
* ``exponential``: ``end + (start - end) * decay ** t``.
* ``step``: ``values[i]`` for ``boundaries[i-1] <= t < boundaries[i]`` (``len(values) ==
  len(boundaries) + 1``).

A schedule is a frozen value built from a plain dict (``from_dict``, e.g. from a sweep YAML) and written
back with ``to_dict``; bad input raises ``ValueError`` naming the offending key and value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

__all__ = ["AlphaClock", "AlphaSchedule", "PRESETS"]

KINDS = ("constant", "linear", "exponential", "step")
CLOCKS = ("global", "per_task")
# Which fields each kind uses (besides kind and clock); other fields must be left at their defaults.
_KIND_FIELDS = {
    "constant": ("alpha",),
    "linear": ("start", "end", "duration"),
    "exponential": ("start", "end", "decay"),
    "step": ("boundaries", "values"),
}

PRESETS: dict[str, dict[str, Any]] = {
    # Sec. 3.3: 1 -> 0 over the first two episodes, then pure time cost.
    "paper_warm_start": {"kind": "linear", "clock": "global", "start": 1.0, "end": 0.0, "duration": 2},
    # Sec. 4.1: 0.9 -> 0.1 linearly over the b repetitions of every task mini-batch.
    "paper_per_task": {"kind": "linear", "clock": "per_task", "start": 0.9, "end": 0.1},
    # Ablation end points.
    "euclidean": {"kind": "constant", "alpha": 1.0},
    "time_cost": {"kind": "constant", "alpha": 0.0},
}


def _check_unit(key: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"alpha schedule: {key} must be a number in [0, 1], got {key}={value!r}") from None
    if not 0.0 <= v <= 1.0:
        raise ValueError(f"alpha schedule: {key} must lie in [0, 1], got {key}={value!r}")
    return v


@dataclass(frozen=True)
class AlphaSchedule:
    kind: str = "constant"
    clock: str = "global"
    alpha: float = 1.0
    start: float = 1.0
    end: float = 0.0
    duration: float | None = None
    decay: float = 0.5
    boundaries: tuple[float, ...] = field(default=())
    values: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"alpha schedule: kind must be one of {KINDS}, got kind={self.kind!r}")
        if self.clock not in CLOCKS:
            raise ValueError(f"alpha schedule: clock must be one of {CLOCKS}, got clock={self.clock!r}")
        defaults = {f.name: f.default for f in fields(self)}
        used = _KIND_FIELDS[self.kind]
        for name in ("alpha", "start", "end", "duration", "decay", "boundaries", "values"):
            if name not in used and getattr(self, name) != defaults[name]:
                raise ValueError(
                    f"alpha schedule: key {name!r} does not apply to kind={self.kind!r} "
                    f"(it uses {list(used)}), got {name}={getattr(self, name)!r}"
                )
        set_ = object.__setattr__
        if self.kind == "constant":
            set_(self, "alpha", _check_unit("alpha", self.alpha))
        if self.kind in ("linear", "exponential"):
            set_(self, "start", _check_unit("start", self.start))
            set_(self, "end", _check_unit("end", self.end))
        if self.kind == "linear":
            if self.duration is None:
                if self.clock == "global":
                    raise ValueError(
                        "alpha schedule: duration is required for a linear schedule on the global clock, "
                        "got duration=None"
                    )
            else:
                try:
                    d = float(self.duration)
                except (TypeError, ValueError):
                    d = math.nan
                if not d > 0 or not math.isfinite(d):
                    raise ValueError(f"alpha schedule: duration must be > 0, got duration={self.duration!r}")
                set_(self, "duration", d)
        if self.kind == "exponential":
            try:
                dec = float(self.decay)
            except (TypeError, ValueError):
                dec = math.nan
            if not 0.0 < dec < 1.0:
                raise ValueError(f"alpha schedule: decay must lie in (0, 1), got decay={self.decay!r}")
            set_(self, "decay", dec)
        if self.kind == "step":
            try:
                bounds = tuple(float(b) for b in self.boundaries)
            except (TypeError, ValueError):
                raise ValueError(
                    f"alpha schedule: boundaries must be a list of numbers, got boundaries={self.boundaries!r}"
                ) from None
            if not isinstance(self.values, list | tuple):
                raise ValueError(f"alpha schedule: values must be a list, got values={self.values!r}")
            vals = tuple(_check_unit(f"values[{i}]", v) for i, v in enumerate(self.values))
            if len(vals) != len(bounds) + 1:
                raise ValueError(
                    f"alpha schedule: a step schedule needs len(values) == len(boundaries) + 1, got "
                    f"values={list(self.values)!r} and boundaries={list(self.boundaries)!r}"
                )
            if any(b2 <= b1 for b1, b2 in zip(bounds, bounds[1:], strict=False)):
                raise ValueError(
                    f"alpha schedule: boundaries must be strictly increasing, got boundaries={list(bounds)!r}"
                )
            set_(self, "boundaries", bounds)
            set_(self, "values", vals)

    # ---------------------------------------------------------------- construction / serialisation
    @classmethod
    def from_dict(cls, spec: dict[str, Any] | AlphaSchedule) -> AlphaSchedule:
        """Build from a plain dict; ``{"preset": name, ...}`` starts from a preset and overrides keys."""
        if isinstance(spec, AlphaSchedule):
            return spec
        if isinstance(spec, str):
            return cls.preset(spec)
        if not isinstance(spec, dict):
            raise ValueError(f"alpha schedule: expected a mapping, got {spec!r}")
        spec = dict(spec)
        if "preset" in spec:
            name = spec.pop("preset")
            if name not in PRESETS:
                raise ValueError(f"alpha schedule: unknown preset={name!r}, known: {sorted(PRESETS)}")
            spec = {**PRESETS[name], **spec}
        known = {f.name for f in fields(cls)}
        for key in spec:
            if key not in known:
                raise ValueError(
                    f"alpha schedule: unknown key {key!r} (value {spec[key]!r}); known keys: {sorted(known)}"
                )
        for key in ("boundaries", "values"):
            if key in spec and isinstance(spec[key], list):
                spec[key] = tuple(spec[key])
        return cls(**spec)

    @classmethod
    def preset(cls, name: str) -> AlphaSchedule:
        if name not in PRESETS:
            raise ValueError(f"alpha schedule: unknown preset={name!r}, known: {sorted(PRESETS)}")
        return cls.from_dict(PRESETS[name])

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (only the keys this kind uses) that ``from_dict`` turns back into ``self``."""
        out: dict[str, Any] = {"kind": self.kind, "clock": self.clock}
        for name in _KIND_FIELDS[self.kind]:
            v = getattr(self, name)
            out[name] = list(v) if isinstance(v, tuple) else v
        if self.kind == "linear" and self.duration is None:
            del out["duration"]
        return out

    # ---------------------------------------------------------------- evaluation
    def value(self, episode: int = 0, repetition: int = 0, repetitions: int = 1) -> float:
        """alpha for the given global ``episode`` (0-based) and ``repetition`` within the task batch."""
        if episode < 0 or repetition < 0 or repetitions < 1:
            raise ValueError(
                f"alpha schedule: need episode >= 0, repetition >= 0, repetitions >= 1, got "
                f"episode={episode}, repetition={repetition}, repetitions={repetitions}"
            )
        t = float(episode if self.clock == "global" else repetition)
        if self.kind == "constant":
            return self.alpha
        if self.kind == "linear":
            duration = self.duration if self.duration is not None else float(repetitions - 1)
            if duration <= 0:
                return self.start
            frac = min(t / duration, 1.0)
            return self.start + (self.end - self.start) * frac
        if self.kind == "exponential":
            return self.end + (self.start - self.end) * self.decay**t
        i = sum(1 for b in self.boundaries if t >= b)
        return self.values[i]


@dataclass
class AlphaClock:
    """Mutable episode counter for a schedule; ``advance()`` once per CO-PILOT episode.

    ``repetition`` is ``episode % repetitions``: Algorithm 3 runs exactly ``repetitions`` episodes on
    each task mini-batch, so the per-task clock restarts with every new mini-batch.
    """

    schedule: AlphaSchedule
    repetitions: int = 1
    episode: int = 0

    def __post_init__(self) -> None:
        self.schedule = AlphaSchedule.from_dict(self.schedule)
        if int(self.repetitions) < 1:
            raise ValueError(f"repetitions must be >= 1, got repetitions={self.repetitions!r}")

    @property
    def repetition(self) -> int:
        return self.episode % self.repetitions

    @property
    def value(self) -> float:
        return self.schedule.value(self.episode, self.repetition, self.repetitions)

    def advance(self) -> float:
        """Count one finished episode; returns the alpha of the next one."""
        self.episode += 1
        return self.value

    def state_dict(self) -> dict[str, Any]:
        return {"schedule": self.schedule.to_dict(), "repetitions": self.repetitions, "episode": self.episode}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.schedule = AlphaSchedule.from_dict(state["schedule"])
        self.repetitions = int(state["repetitions"])
        self.episode = int(state["episode"])
