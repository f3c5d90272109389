"""What a sweep trial is, read off its flat Tune config: the spec it came from, its settings at the
values the run uses, its configuration's name and the labels the progress lines, the MLflow tags and the
report group runs by. No Ray import (the driver's callbacks and the MLflow side use it).

A trial's Tune config is ``{dotted searched params..., "seed": s, "_spec_path": p}``; the labels an
algorithm's runs carry (tree depth K, repetitions b, the alpha schedule) are declared next to its
settings (`LABELS` in its settings module, read by the registry).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import Any

import numpy as np
import yaml

from copilot_ray.keys import ENV_PARAM, PLAN_SEEDS, SEED_PARAM, SEEDS_KEY, SPEC_PATH_KEY, VARIANT_PARAM
from copilot_ray.registry import get_algorithm
from copilot_ray.sweep_spec import build_algorithm_config, load_spec


def load_spec_cached(path: str):
    """The spec at ``path``, loaded once per process (trials and callbacks ask for it often)."""
    spec = _SPEC_CACHE.get(path)
    if spec is None:
        spec = _SPEC_CACHE[path] = load_spec(path)
    return spec


_SPEC_CACHE: dict[str, Any] = {}


def algorithm_config(config: Mapping[str, Any]) -> Any:
    """The algorithm config of a sweep trial's flat Tune config (spec path + searched values + seed)."""
    spec = load_spec_cached(str(config[SPEC_PATH_KEY]))
    return build_algorithm_config(trial_flat(config), spec)


def stacked_seeds(config: Mapping[str, Any]) -> list[int] | None:
    """The seeds of a stacked trial's Tune config (spec `seeds_per_trial` > 1), None for a one-seed trial."""
    seeds = config.get(SEEDS_KEY)
    return None if seeds is None else [int(s) for s in seeds]


def seed_config(config: Mapping[str, Any], seed: int) -> dict[str, Any]:
    """A stacked trial's Tune config as seed `seed`'s one-seed trial config."""
    out = {k: v for k, v in config.items() if k != SEEDS_KEY}
    out[SEED_PARAM] = int(seed)
    return out


def trial_flat(config: Mapping[str, Any]) -> dict[str, Any]:
    """A Tune trial config without the fixed bookkeeping keys: searched dotted params + seed."""
    return {k: v for k, v in config.items() if not str(k).startswith("_")}


def _fmt_value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, Mapping):
        return "{" + ",".join(f"{k}:{_fmt_value(v)}" for k, v in value.items()) + "}"
    return str(value)


def config_key(flat: Mapping[str, Any]) -> str:
    """Names a configuration without its seed (or a stack's seeds): sorted ``key=value`` of the searched params, or ``default``."""
    items = sorted((k, v) for k, v in flat.items() if k not in (SEED_PARAM, PLAN_SEEDS))
    return ",".join(f"{k}={_fmt_value(v)}" for k, v in items) or "default"


def alpha_schedule_label(merged: Mapping[str, Any], default: str = "") -> str:
    """The preset name or kind of the alpha schedule a trial uses (`default`: when none is given)."""
    whole = merged.get("alpha_schedule")
    dotted = sorted(k.split(".", 1)[1] for k in merged if str(k).startswith("alpha_schedule."))
    if "kind" in dotted:
        return str(merged["alpha_schedule.kind"])
    if isinstance(whole, Mapping):
        base = str(whole.get("preset") or whole.get("kind", "custom"))
    elif whole is not None:
        base = str(whole)
    else:
        base = default
    return base + ("*" if dotted else "")  # '*': preset with some fields overridden


def describe_trial(config: Mapping[str, Any]) -> dict[str, Any]:
    """Everything the progress lines and the MLflow tags say about one trial (built on the driver)."""
    spec = load_spec_cached(str(config[SPEC_PATH_KEY]))
    entry = get_algorithm(spec.algorithm)
    settings = entry.settings
    flat = trial_flat(config)
    algo_config = build_algorithm_config(flat, spec)
    merged = spec.merged(flat)
    seeds = stacked_seeds(config)
    # (a stacked trial's progress lines name all its seeds: "0+1+2")
    seed = "+".join(map(str, seeds)) if seeds else flat.get(SEED_PARAM, spec.seeds[0])
    effective = effective_settings(algo_config, settings)
    return {
        "spec": spec,
        "flat": flat,
        "algo_config": algo_config,
        "config_key": config_key(flat),
        "algorithm": spec.algorithm,
        "env": flat.get(ENV_PARAM, spec.env.ids[0]),
        # The labels the algorithm declares (LABELS next to its settings); None where it has none.
        "K": effective.get(entry.labels["K"]) if "K" in entry.labels else None,
        "b": effective.get(entry.labels["b"]) if "b" in entry.labels else None,
        "alpha_schedule": alpha_schedule_label(merged, settings["alpha_schedule"].default)
        if "alpha_schedule" in entry.labels
        else "",
        "preset": getattr(algo_config, "preset", None) or "default",
        "variant": flat.get(VARIANT_PARAM, ""),
        "seed": seed,
        "settings": effective,
        # What it uses that an agent learning from its own episodes does not (copilot_ray.privileges).
        "privileges": entry.privileges(effective),
    }


def effective_settings(algo_config: Any, settings: Mapping[str, Any]) -> dict[str, Any]:
    """Every setting of the trial's algorithm at the value the run uses (dotted keys read nested dicts)."""
    if hasattr(algo_config, "setting_values"):
        # A settings record (copilot_ray.settings.record_class) knows its own: `hrl.c` is its field `hrl_c`.
        return {k: v for k, v in algo_config.setting_values().items() if k in settings}
    out: dict[str, Any] = {}
    for key, setting in settings.items():
        if key == "alpha_schedule":
            continue  # its fields follow as alpha_schedule.<field>
        try:
            if "." not in key:
                out[key] = getattr(algo_config, key)
            else:
                container = getattr(algo_config, setting.target)
                if setting.field in container:
                    out[key] = container[setting.field]
        except (AttributeError, TypeError, IndexError):
            continue
    return out


def _plain(value: Any) -> Any:
    """A YAML-safe copy (classes, callables and the like become their repr)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(v) for v in value]
    if value is None or type(value) in (bool, int, float, str):
        return value

    if isinstance(value, enum.Enum):
        return _plain(value.value)
    if isinstance(value, bool | int | float | str):  # subclasses of the scalars
        return _base_scalar(value)
    try:
        if isinstance(value, np.generic):
            return value.item()
    except ImportError:  # pragma: no cover
        pass
    return repr(value)


def _base_scalar(value: Any) -> Any:
    for base in (bool, int, float, str):
        if isinstance(value, base):
            return base(value)
    return repr(value)


def trial_config_yaml(info: Mapping[str, Any]) -> str:

    spec = info["spec"]
    try:
        algo = info["algo_config"].to_dict()
    except Exception as err:  # noqa: BLE001 - the artifact must not fail the sweep
        algo = f"<to_dict failed: {err}>"
    doc = {
        "sweep": spec.name,
        "spec": spec.source,
        "trial": info["flat"],
        "seed": info["seed"],
        "config_key": info["config_key"],
        "env": {"id": info["env"], "config": dict(spec.env.config)},
        "settings": info["settings"],
        "algorithm": spec.algorithm,
        "algorithm_config": algo,
    }
    return yaml.safe_dump(_plain(doc), sort_keys=False, default_flow_style=None, width=120)


def env_params(spec: Any, env_id: str) -> dict[str, Any]:
    """The environment as MLflow params: ``env.id`` (the trial's) and ``env.config.<key>``."""
    return {ENV_PARAM: env_id, **{f"env.config.{k}": v for k, v in spec.env.config.items()}}
