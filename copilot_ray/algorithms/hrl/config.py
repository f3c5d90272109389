"""HRLConfig: what one HRL trial runs (no Ray; the registry's config class).

One field per setting (`hrl.c` is `hrl_c`), each level's SAC settings as a dict (`low`, `high`), every
default read off the settings table (`copilot_ray.settings.record_class`); values are checked on
construction, combinations too.
"""

from __future__ import annotations

from copilot_ray.algorithms.hrl.settings import LEVELS, SETTINGS, combination_problems
from copilot_ray.settings import record_class

_Record = record_class("HRLConfig", SETTINGS, nested=LEVELS)


class HRLConfig(_Record):
    def __post_init__(self) -> None:
        super().__post_init__()
        values = self.setting_values()
        for keys_, value, why in combination_problems(values):
            raise ValueError(f"HRLConfig: {', '.join(keys_)}={value!r} is invalid: {why}")
