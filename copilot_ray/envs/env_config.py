"""Checking an env's `env_config`, the same way for every env here: merged over the env's defaults,
unknown keys and bad values refused with an error that names the key and the value."""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np


def merged_config(env_name: str, config: Mapping[str, Any], defaults: Mapping[str, Any]) -> dict[str, Any]:
    """`config` over `defaults`; a ValueError naming the first unknown key and listing the valid ones."""
    unknown = [k for k in config if k not in defaults]
    if unknown:
        raise ValueError(
            f"unknown {env_name} env_config key {unknown[0]!r}; valid keys: {', '.join(sorted(defaults))}"
        )
    return {**defaults, **config}


def bad_value(cfg: Mapping[str, Any], key: str, need: str) -> ValueError:
    """The error for `cfg[key]`: `env_config['key'] = value: must be <need>`."""
    return ValueError(f"env_config[{key!r}] = {cfg[key]!r}: must be {need}")


def is_number(value: Any) -> bool:
    """A finite real number (a bool is not one)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and bool(np.isfinite(value))


def is_integer(value: Any) -> bool:
    """An integer (a bool is not one)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)
