"""A setting of an algorithm, declared once: key, type, default, rule and a one-line doc.

An algorithm's module lists its settings (`copilot_ray.algorithms.copilot.settings.SETTINGS`); the
config's validation, the sweep spec's keys and ranges, the command line and the settings page's tables (docs/settings.md)
are all read off that list, so a rule cannot disagree between them.

No Ray, numpy or torch here: sweep specs are validated against settings before anything starts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

# The deepest sub-goal tree any setting allows: 2^(K+1) - 1 sub-tasks per task, so K = 10 is already 2047
# (the one place this limit is written: the algorithms' tree_depth settings and the registry's per-layer
# metrics read it from here).
MAX_TREE_DEPTH = 10
# What a search domain may produce for a setting of each kind (an int range fits a float setting too).
SETTING_KINDS = ("int", "float", "bool", "str", "list", "schedule")


def is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


@dataclass(frozen=True)
class Setting:
    """One setting. `check(value)` is its rule and `rule` says it in words ("must be <rule>").

    key: its name everywhere (config attribute, spec key, CLI flag); a dotted key is one field of a
    nested dict (`planner.std` is `config.planner["std"]`). target: where the algorithm's
    config class puts it (the algorithm's settings module documents its targets).
    """

    key: str
    kind: str  # one of SETTING_KINDS
    target: str
    default: Any
    doc: str
    check: Callable[[Any], bool] = field(repr=False, compare=False)
    rule: str
    choices: tuple[Any, ...] = ()  # kind "str": the allowed values
    why: str = ""  # why this default, when it departs from or decides a reading of the paper
    on_cli: bool = True  # offered as a `python -m copilot_ray.train` flag
    # The privileges (copilot_ray.privileges) a value of this setting grants its method: value -> names.
    grants: Callable[[Any], tuple[str, ...]] | None = field(default=None, repr=False, compare=False)

    @property
    def field(self) -> str:
        """The name inside its target: `std` for `planner.std`, the key otherwise."""
        return self.key.split(".", 1)[1] if "." in self.key else self.key

    @property
    def flag(self) -> str:
        """The command-line flag: `planner.std_final` -> `--planner-std-final`."""
        return "--" + self.key.replace(".", "-").replace("_", "-")

    def problem(self, value: Any) -> str | None:
        """None when `value` is allowed, else "must be <rule>"."""
        try:
            ok = bool(self.check(value))
        except (TypeError, ValueError):
            ok = False
        return None if ok else f"must be {self.rule}"


def int_setting(
    key: str,
    target: str,
    default: Any,
    doc: str,
    lo: int,
    hi: int | None = None,
    *,
    note: str = "",
    **kw: Any,
) -> Setting:
    """An integer in [lo, hi] (hi None: no upper bound); `note` follows the rule in messages."""
    rule = (f"an integer in [{lo}, {hi}]" if hi is not None else f"an integer >= {lo}") + note
    return Setting(
        key,
        "int",
        target,
        default,
        doc,
        lambda v: is_int(v) and v >= lo and (hi is None or v <= hi),
        rule,
        **kw,
    )


def float_setting(
    key: str,
    target: str,
    default: Any,
    doc: str,
    lo: float,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    optional: bool = False,
    **kw: Any,
) -> Setting:
    """A finite number in a range; `optional`: null (None, "off") too."""

    def check(v: Any) -> bool:
        if v is None:
            return optional
        if not is_number(v):
            return False
        above = v > lo if lo_open else v >= lo
        below = True if hi is None else (v < hi if hi_open else v <= hi)
        return above and below

    if hi is None:
        rule = f"a number {'>' if lo_open else '>='} {lo:g}"
    else:
        rule = f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    rule += " or null (off)" if optional else ""
    return Setting(key, "float", target, default, doc, check, rule, **kw)


def bool_setting(key: str, target: str, default: bool, doc: str, **kw: Any) -> Setting:
    return Setting(key, "bool", target, default, doc, lambda v: isinstance(v, bool), "true or false", **kw)


def choice_setting(
    key: str,
    target: str,
    default: Any,
    doc: str,
    choices: tuple[str, ...],
    *,
    optional: bool = False,
    **kw: Any,
) -> Setting:
    """One of `choices`; `optional`: null too."""
    rule = f"one of {list(choices)}" + (" or null" if optional else "")
    return Setting(
        key,
        "str",
        target,
        default,
        doc,
        lambda v: v in choices or (optional and v is None),
        rule,
        choices=choices,
        **kw,
    )


def sizes_setting(key: str, target: str, default: list[int], doc: str, **kw: Any) -> Setting:
    """Hidden layer sizes: a non-empty list of positive integers."""
    return Setting(
        key,
        "list",
        target,
        default,
        doc,
        lambda v: isinstance(v, list) and len(v) > 0 and all(is_int(x) and x >= 1 for x in v),
        "a non-empty list of integers >= 1 (hidden layer sizes)",
        **kw,
    )


def numbers_setting(
    key: str,
    target: str,
    default: Any,
    doc: str,
    lo: float | None = None,
    hi: float | None = None,
    what: str = "numbers",
    **kw: Any,
) -> Setting:
    """A list of finite numbers, each in [lo, hi]."""

    def check(v: Any) -> bool:
        return isinstance(v, list) and all(
            is_number(x) and (lo is None or x >= lo) and (hi is None or x <= hi) for x in v
        )

    return Setting(key, "list", target, default, doc, check, f"a list of {what}", **kw)


PARAM_LIMIT = 500  # MLflow rejects longer param values


def logged_text(value: Any) -> str:
    """A setting's value as runs log it among their MLflow params: a string as it is, anything else its
    repr, cut to MLflow's limit (the report reads old runs' params against this checkout's defaults in
    the same form)."""
    return (value if isinstance(value, str) else repr(value))[:PARAM_LIMIT]


def markdown_value(value: Any) -> str:
    """A setting's value as a README table cell."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    return f"`{value}`"


def replace_between(text: str, begin: str, end: str, body: str) -> str:
    """`text` with what lies between the marker lines `begin` and `end` replaced by `body`."""
    head, sep, rest = text.partition(begin)
    if not sep:
        raise ValueError(f"no {begin!r} marker")
    _, sep, tail = rest.partition(end)
    if not sep:
        raise ValueError(f"no {end!r} marker after {begin!r}")
    return f"{head}{begin}\n{body}\n{end}{tail}"


def problems(settings: Mapping[str, Setting], values: Mapping[str, Any]) -> list[tuple[str, Any, str]]:
    """(key, value, message) for every value that is not a setting or breaks its setting's rule."""
    out = []
    for key, value in values.items():
        setting = settings.get(key)
        if setting is None:
            out.append((key, value, "unknown key"))
        elif (msg := setting.problem(value)) is not None:
            out.append((key, value, msg))
    return out


# ------------------------------------------------------------------------------- values to a config
def effective(
    settings: Mapping[str, Setting], values: Mapping[str, Any], presets: Mapping[str, Mapping[str, Any]] = {}
) -> dict[str, Any]:
    """Every setting at the value a run of flat `values` uses: its default, then the named preset's
    (`values["preset"]`; a preset's nested dicts are its dotted keys), then `values` themselves."""
    out = {key: s.default for key, s in settings.items()}
    for key, value in presets.get(values.get("preset") or "", {}).items():
        if isinstance(value, Mapping) and key not in settings:
            out.update({f"{key}.{field}": v for field, v in value.items() if f"{key}.{field}" in settings})
        elif key in settings:
            out[key] = value
    out.update({k: v for k, v in values.items() if k in settings})
    return out


def route(settings: Mapping[str, Setting], values: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Flat `values` grouped by where their settings go: `{target: {field: value}}` (`planner.std` ->
    `{"planner": {"std": ...}}`, a top-level key -> `{target: {key: ...}}`). Unknown keys raise KeyError."""
    out: dict[str, dict[str, Any]] = {}
    for key, value in values.items():
        setting = settings[key]
        out.setdefault(setting.target, {})[setting.field] = value
    return out


def check(settings: Mapping[str, Setting], values: Mapping[str, Any], owner: str) -> None:
    """Raises ValueError with one line per value that breaks its setting's rule (or is no setting),
    each "<owner>: <key>=<value> is invalid: must be <rule>": the one message every config gives."""
    found = problems(settings, values)
    if found:
        raise ValueError(
            "\n".join(f"{owner}: {key}={value!r} is invalid: {why}" for key, value, why in found)
        )


def record_class(
    name: str,
    settings: Mapping[str, Setting],
    nested: tuple[str, ...] = (),
    doc: str = "",
    with_run: bool = True,
) -> type:
    """A frozen dataclass holding one run (env_id, env_config, seed, torch_threads) and every setting of `settings` (the config of
    an algorithm that is not an RLlib Algorithm): one field per setting, dots as underscores (`hrl.c`
    -> `hrl_c`), one dict per `nested` target (`planner.std` -> `planner["std"]`), each defaulting to the
    table's default (no field re-declares one). Values are checked on construction (`check`);
    `from_settings(values, run)` builds one from flat setting values and a RunContext, `setting_values()`
    gives them back, `to_dict()` is `dataclasses.asdict`. Subclass it to add methods. `with_run=False`: the
    settings alone (no run fields, no `from_settings`)."""
    import copy
    import dataclasses

    fields: list[tuple] = (
        [
            ("env_id", str),
            ("env_config", dict, dataclasses.field(default_factory=dict)),
            ("seed", int, dataclasses.field(default=0)),
            ("torch_threads", int, dataclasses.field(default=1)),
        ]
        if with_run
        else []
    )
    for target in nested:
        defaults = {s.field: s.default for s in settings.values() if s.target == target}
        fields.append((target, dict, dataclasses.field(default_factory=lambda d=defaults: copy.deepcopy(d))))
    for key, s in settings.items():
        if s.target not in nested:
            mutable = isinstance(s.default, list | dict)
            default = (
                dataclasses.field(default_factory=lambda d=s.default: copy.deepcopy(d))
                if mutable
                else (dataclasses.field(default=s.default))
            )
            fields.append((key.replace(".", "_"), Any, default))

    def setting_values(self) -> dict[str, Any]:
        """`{setting key: value}` of every setting (dotted keys)."""
        return {
            key: getattr(self, s.target)[s.field]
            if s.target in nested
            else getattr(self, key.replace(".", "_"))
            for key, s in settings.items()
        }

    def __post_init__(self) -> None:
        check(settings, self.setting_values(), name)
        for target in nested:
            unknown = sorted(
                set(getattr(self, target)) - {s.field for s in settings.values() if s.target == target}
            )
            if unknown:
                raise ValueError(f"{name}: {target}.{unknown[0]} is not a setting")

    def from_settings(cls, values: Mapping[str, Any], run: Any):
        """Flat setting values (dotted keys) + a registry RunContext (env, seed, the process's CPUs)."""
        check(settings, values, name)
        kwargs: dict[str, Any] = {}
        for target, given in route(settings, values).items():
            if target in nested:
                defaults = {s.field: s.default for s in settings.values() if s.target == target}
                kwargs[target] = {**defaults, **given}
        kwargs.update({k.replace(".", "_"): v for k, v in values.items() if settings[k].target not in nested})
        return cls(
            env_id=run.env_id,
            env_config=dict(run.env_config),
            seed=int(run.seed),
            torch_threads=max(1, int(getattr(run, "num_cpus_for_main_process", 1) or 1)),
            **kwargs,
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    namespace = {
        "__doc__": doc,
        "setting_values": setting_values,
        "__post_init__": __post_init__,
        "to_dict": to_dict,
    }
    if with_run:
        namespace["from_settings"] = classmethod(from_settings)
    return dataclasses.make_dataclass(name, fields, frozen=True, namespace=namespace)


_ANNOTATIONS = {"int": int, "float": float, "bool": bool, "str": str, "list": list, "schedule": Any}


def keyword_arguments(
    table: Mapping[str, Setting], targets: tuple[str, ...], nested: tuple[str, ...] = ()
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorates a `method(self, **settings)` setter with named keyword arguments read off `table`:
    every undotted setting whose target is in `targets`, and one dict per `nested` target (its dotted
    settings' defaults). help() and signature-reading editors then show each name, type, default and
    doc; the method body is unchanged (arguments left out keep their current value)."""
    import inspect

    def decorate(method: Callable[..., Any]) -> Callable[..., Any]:
        params = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
        lines = []
        for key, s in table.items():
            if "." in key or s.target not in targets:
                continue
            params.append(
                inspect.Parameter(
                    key, inspect.Parameter.KEYWORD_ONLY, default=s.default, annotation=_ANNOTATIONS[s.kind]
                )
            )
            lines.append(f"    {key} ({s.kind}, default {s.default!r}): {s.doc}")
        for name in nested:
            fields = {s.field: s.default for s in table.values() if s.target == name and "." in s.key}
            params.append(
                inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=fields, annotation=dict)
            )
            lines.append(f"    {name} (dict, updates the current one key by key; defaults {fields!r})")
        method.__signature__ = inspect.Signature(params)  # type: ignore[attr-defined]
        method.__doc__ = (
            f"{method.__doc__ or ''}\n\n    Arguments (left out: unchanged; a new config holds these defaults):\n"
            + "\n".join(lines)
        )
        return method

    return decorate
