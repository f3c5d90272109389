"""The sweep spec's sections, one pydantic model each (search domains, env, searcher, scheduler, stop,
fault tolerance, resources, tracking, best_of), each checked on its own; `models.SweepSpec` puts them
together and checks them across sections."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from copilot_ray.settings import is_int, is_number
from copilot_ray.store import tracking_uri_problem
from copilot_ray.sweep_spec.errors import Issue, Issues, did_you_mean
from copilot_ray.sweep_spec.estimate import MIN_EVALUATIONS


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, populate_by_name=False)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            known = [f.alias or n for n, f in cls.model_fields.items()]
            unknown = [k for k in data if k not in known]
            if unknown:
                # Raising here stops pydantic's own checks: say what is missing too, so that one run of
                # --check lists every problem at this level.
                required = [f.alias or n for n, f in cls.model_fields.items() if f.is_required()]
                missing = [k for k in required if k not in data]
                raise Issues(
                    [
                        Issue(
                            str(k),
                            data[k],
                            f"unknown key{did_you_mean(str(k), known)} (known keys: {', '.join(known)})",
                            show_value=False,
                        )
                        for k in unknown
                    ]
                    + [Issue(k, None, "required key is missing", show_value=False) for k in missing]
                )
        return data


class ParamSearch(_Model):
    """One searched parameter: exactly one of grid / int / float / categorical."""

    grid: list[Any] | None = None
    int_: list[int] | None = Field(default=None, alias="int")
    float_: list[float] | None = Field(default=None, alias="float")
    categorical: list[Any] | None = None
    log: bool = False
    step: int | float | None = None
    when: dict[str, dict[str, ParamSearch]] | None = None

    @property
    def domain(self) -> str:
        for name in ("grid", "int", "float", "categorical"):
            if self.values_of(name) is not None:
                return name
        raise AssertionError("validated ParamSearch has a domain")

    def values_of(self, name: str) -> list[Any] | None:
        return {"grid": self.grid, "int": self.int_, "float": self.float_, "categorical": self.categorical}[
            name
        ]

    @property
    def values(self) -> list[Any]:
        return list(self.values_of(self.domain) or [])

    @model_validator(mode="after")
    def _one_domain(self) -> ParamSearch:
        given = [n for n in ("grid", "int", "float", "categorical") if self.values_of(n) is not None]
        if len(given) != 1:
            raise Issue(
                "",
                None,
                "give exactly one of grid, int, float, categorical"
                + (f" (got {', '.join(given)})" if given else ""),
                show_value=False,
            )
        domain = given[0]
        values = self.values_of(domain)
        issues: list[Issue] = []
        if domain in ("grid", "categorical"):
            if not values:
                issues.append(Issue(domain, values, f"an empty {domain} has nothing to run; list >= 1 value"))
            dupes = [v for i, v in enumerate(values) if v in values[:i]]
            if dupes:
                issues.append(Issue(domain, values, f"duplicate value {dupes[0]!r} would run twice"))
            if self.log or self.step is not None:
                issues.append(Issue(domain, values, "log and step apply to int and float ranges only"))
        else:
            if len(values) != 2:
                issues.append(Issue(domain, values, f"{domain} takes [low, high]"))
            else:
                low, high = values
                if low > high:
                    issues.append(Issue(domain, values, f"low {low!r} > high {high!r}"))
                if self.log and low <= 0:
                    issues.append(Issue(domain, values, f"a log range needs low > 0, got low {low!r}"))
            if self.step is not None:
                if domain == "int" and not (is_int(self.step) and self.step >= 1):
                    issues.append(Issue("step", self.step, "an int range's step must be an integer >= 1"))
                if domain == "float" and not (is_number(self.step) and self.step > 0):
                    issues.append(Issue("step", self.step, "step must be a number > 0"))
                if self.log and self.step != 1 and domain == "int" or self.log and domain == "float":
                    issues.append(Issue("step", self.step, "log ranges cannot have a step (Optuna)"))
        if self.when is not None:
            if domain != "categorical":
                issues.append(
                    Issue("when", None, "conditional parameters need a categorical domain", show_value=False)
                )
            else:
                labels = [str(v) for v in values]
                for choice in self.when:
                    if choice not in labels:
                        issues.append(
                            Issue(
                                f"when.{choice}",
                                choice,
                                f"not one of the categorical values {labels}{did_you_mean(choice, labels)}",
                            )
                        )
        if issues:
            raise Issues(issues)
        return self

    def describe(self) -> str:
        d = self.domain
        if d in ("grid", "categorical"):
            return f"{d} {self.values}"
        extra = (" log" if self.log else "") + (f" step {self.step}" if self.step is not None else "")
        return f"{d} [{self.values[0]}, {self.values[1]}]{extra}"


class EnvSpec(_Model):
    id: str | list[str]  # several: a grid axis (trial param `env.id`), every configuration on each
    config: dict[str, Any] = Field(default_factory=dict)

    @property
    def ids(self) -> list[str]:
        return [self.id] if isinstance(self.id, str) else list(self.id)


class SearcherSpec(_Model):
    type: Literal["grid", "optuna"] = "grid"
    sampler: Literal["tpe", "random", "cmaes"] | None = None
    metric: str | None = None
    mode: Literal["max", "min"] | None = None
    num_samples: int | None = None
    seed: int | None = None

    @model_validator(mode="after")
    def _per_type(self) -> SearcherSpec:
        issues = []
        if self.type == "grid":
            for key in ("sampler", "num_samples", "seed"):
                if getattr(self, key) is not None:
                    issues.append(Issue(key, getattr(self, key), "only an optuna searcher takes it"))
        else:
            self.sampler = self.sampler or "tpe"
            if self.metric is None:
                issues.append(Issue("metric", None, "an optuna searcher needs the metric it optimises"))
            if self.mode is None:
                issues.append(Issue("mode", None, "an optuna searcher needs mode: max or min"))
            if self.num_samples is None or self.num_samples < 1:
                issues.append(Issue("num_samples", self.num_samples, "must be an integer >= 1"))
            if self.seed is None:
                self.seed = 0
        if (self.metric is None) != (self.mode is None) and self.type == "grid":
            issues.append(
                Issue("mode" if self.mode is None else "metric", None, "give metric and mode together")
            )
        if issues:
            raise Issues(issues)
        return self


class SchedulerSpec(_Model):
    """Early stopping under Tune; time is measured in environment steps (keys.ENV_STEPS)."""

    type: Literal["asha", "median_stopping"]
    max_t: int | None = None
    grace_period: int | None = None
    reduction_factor: float | None = None
    min_samples_required: int | None = None

    @model_validator(mode="after")
    def _per_type(self) -> SchedulerSpec:
        issues = []
        own = {
            "asha": ("max_t", "grace_period", "reduction_factor"),
            "median_stopping": ("grace_period", "min_samples_required"),
        }
        for key in ("max_t", "grace_period", "reduction_factor", "min_samples_required"):
            if key not in own[self.type] and getattr(self, key) is not None:
                issues.append(Issue(key, getattr(self, key), f"does not apply to type {self.type}"))
        if self.type == "asha":
            if self.max_t is None or self.max_t < 1:
                issues.append(Issue("max_t", self.max_t, "ASHA needs max_t >= 1 (environment steps)"))
            self.grace_period = 1 if self.grace_period is None else self.grace_period
            self.reduction_factor = 3.0 if self.reduction_factor is None else self.reduction_factor
            if self.reduction_factor <= 1:
                issues.append(Issue("reduction_factor", self.reduction_factor, "must be > 1"))
        else:
            self.grace_period = 1 if self.grace_period is None else self.grace_period
            self.min_samples_required = 3 if self.min_samples_required is None else self.min_samples_required
            if self.min_samples_required < 1:
                issues.append(Issue("min_samples_required", self.min_samples_required, "must be >= 1"))
        if self.grace_period < 1:
            issues.append(Issue("grace_period", self.grace_period, "must be >= 1 (environment steps)"))
        elif self.max_t is not None and self.max_t >= 1 and self.grace_period > self.max_t:
            issues.append(Issue("grace_period", self.grace_period, f"must be <= max_t ({self.max_t})"))
        if issues:
            raise Issues(issues)
        return self


class StopSpec(_Model):
    """When a trial ends. `min_evaluations` (default MIN_EVALUATIONS): the fewest evaluations a trial
    must be sure to get before it does (sweep_spec/estimate.py); lower it only for smoke runs, where a trial
    only has to run."""

    env_steps: int | None = None
    iterations: int | None = None
    min_evaluations: int = MIN_EVALUATIONS

    @model_validator(mode="after")
    def _one(self) -> StopSpec:
        if self.env_steps is None and self.iterations is None:
            raise Issue("", None, "give env_steps and/or iterations", show_value=False)
        issues = [
            Issue(k, getattr(self, k), "must be an integer >= 1")
            for k in ("env_steps", "iterations")
            if getattr(self, k) is not None and getattr(self, k) < 1
        ]
        if self.min_evaluations < 0:
            issues.append(Issue("min_evaluations", self.min_evaluations, "must be an integer >= 0"))
        if issues:
            raise Issues(issues)
        return self


class FaultToleranceSpec(_Model):
    """How a trial survives a crash: checkpoints every ``checkpoint_every`` iterations (a retried or
    resumed trial repeats at most that many - 1), and ``max_failures`` retries from the last one (-1:
    without limit) before the trial is marked ERROR and the sweep goes on without it."""

    checkpoint_every: int = 1
    max_failures: int = 2

    @model_validator(mode="after")
    def _ranges(self) -> FaultToleranceSpec:
        issues = []
        if self.checkpoint_every < 1:
            issues.append(Issue("checkpoint_every", self.checkpoint_every, "must be an integer >= 1"))
        if self.max_failures < -1:
            issues.append(Issue("max_failures", self.max_failures, "must be >= 0, or -1 for no limit"))
        if issues:
            raise Issues(issues)
        return self


def _number(x: float) -> float | int:
    """A float as the user would have written it (1, not 1.0) in an error message."""
    return int(x) if float(x).is_integer() else x


class ResourcesSpec(_Model):
    max_concurrent_trials: int = 1
    num_env_runners: int = 0
    cpus_per_trial: int | None = None
    # GPUs of each trial's learner (RLlib's num_gpus_per_learner); fractions share one GPU, as in Tune.
    gpus_per_trial: float = 0.0

    @model_validator(mode="after")
    def _sizes(self) -> ResourcesSpec:
        issues = []
        g = self.gpus_per_trial
        if g < 0 or (g > 1 and g != int(g)):
            issues.append(
                Issue("gpus_per_trial", _number(g), "must be >= 0, and a whole number above 1 (Ray's rule)")
            )
        if self.max_concurrent_trials < 1:
            issues.append(Issue("max_concurrent_trials", self.max_concurrent_trials, "must be >= 1"))
        if self.num_env_runners < 0:
            issues.append(Issue("num_env_runners", self.num_env_runners, "must be >= 0"))
        need = 1 + max(self.num_env_runners, 0)
        if self.cpus_per_trial is None:
            self.cpus_per_trial = need
        elif self.cpus_per_trial < need:
            issues.append(
                Issue(
                    "cpus_per_trial",
                    self.cpus_per_trial,
                    f"a trial needs 1 CPU for its driver + 1 per env runner = {need}",
                )
            )
        if issues:
            raise Issues(issues)
        return self


class TrackingSpec(_Model):
    uri: str | None = None
    storage: str = "results/"
    # RLlib's own connector and env-runner timers (~100 metrics per trial): left out of MLflow unless
    # asked for, so that the runs page shows what the experiment measures.
    rllib_timers: bool = False

    @model_validator(mode="after")
    def _known_store(self) -> TrackingSpec:
        if self.uri is not None and (why := tracking_uri_problem(self.uri)) is not None:
            raise Issue("uri", self.uri, why)
        return self
