"""Reading a spec: a YAML file (one spec, or several as YAML documents) or an already-parsed mapping,
validated into `SweepSpec`s, every problem of every section and part reported together."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from copilot_ray.sweep_spec.comparison import comparison_problems, link_stages
from copilot_ray.sweep_spec.errors import Issue, Issues, SpecError, short
from copilot_ray.sweep_spec.models import SweepSpec
from copilot_ray.sweep_spec.yaml_loader import read_yaml_documents, read_yaml_file


def _format_validation_error(err: ValidationError, source: str) -> list[str]:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in e["loc"]).replace(".[", "[")
        exc = (e.get("ctx") or {}).get("error")
        if isinstance(exc, Issues):
            lines += [f"{source}: {i.text(loc)}" for i in exc.issues]
        elif isinstance(exc, Issue):
            lines.append(f"{source}: {exc.text(loc)}")
        elif e["type"] == "missing":
            lines.append(f"{source}: {loc}: required key is missing")
        else:
            lines.append(f"{source}: {loc}: {short(e.get('input'))} is invalid: {e['msg']}")
    return lines


def parse_spec(data: Any, source: str = "<spec>") -> SweepSpec:
    """Validate an already-parsed spec (a mapping); raises SpecError naming ``source``."""
    if not isinstance(data, dict):
        raise SpecError([f"{source}: the spec must be a mapping of keys (name, env, ...), got {short(data)}"])
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as err:
        lines = _format_validation_error(err, source)
        raise SpecError(lines + _across_sections(data, err, source, lines)) from None
    spec._source = source
    spec._document = copy.deepcopy(data)
    return spec


# Stand-ins for required sections that failed on their own, so that the checks across sections still run.
_STAND_INS = {"name": "spec", "stop": {"env_steps": 10**9, "min_evaluations": 0}}


def _across_sections(data: dict, err: ValidationError, source: str, seen: list[str]) -> list[str]:
    """The checks across sections (keys against the algorithm's settings, the searcher's metric, ...),
    which pydantic skips once a section fails on its own: run again with the failed sections set aside
    (defaults, or stand-ins for required ones), keeping what they find about the other sections. So a
    spec with mistakes in several sections gets them all in one report."""
    failed = {str(e["loc"][0]) for e in err.errors() if e["loc"]}
    if not failed or failed - set(SweepSpec.model_fields) or "env" in failed or "algorithm" in failed:
        return []
    rest = {k: v for k, v in data.items() if k not in failed}
    rest.update({k: v for k, v in _STAND_INS.items() if k in failed})
    try:
        SweepSpec.model_validate(rest)
    except ValidationError as again:
        prefixes = tuple(f"{source}: {k}" for k in failed)
        return [
            line
            for line in _format_validation_error(again, source)
            if line not in seen and not line.startswith(prefixes)
        ]
    return []


def load_specs(path: str | Path) -> list[SweepSpec]:
    """Every spec of a file: one, or several YAML documents (``---`` between them), each a complete spec
    with its own ``name`` (e.g. one algorithm each: a Tune experiment runs one trainable). All are
    validated before this returns; problems name the part they are in."""
    documents = read_yaml_documents(path)
    if len(documents) == 1:
        spec = parse_spec(documents[0], str(path))
        if problems := link_stages([spec]):
            raise SpecError(problems)
        return [spec]
    specs, problems = [], []
    for i, doc in enumerate(documents, start=1):
        try:
            specs.append(parse_spec(doc, str(path)))
        except SpecError as err:
            problems += [f"part {i} of {len(documents)}: {line}" for line in err.problems]
    names = [s.name for s in specs]
    for name in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"{path}: name: {name!r} is invalid: every part of a spec file needs its own name")
    if not problems:
        problems += link_stages(specs) + comparison_problems(specs)
    if problems:
        raise SpecError(problems)
    return specs


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a sweep YAML file; raises SpecError (a ValueError) naming file, key path, value."""
    return parse_spec(read_yaml_file(path), str(path))
