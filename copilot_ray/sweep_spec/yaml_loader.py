"""YAML as a spec reader expects it: `1e-3` is a float (YAML 1.1 reads a string) and duplicate keys are
errors (PyYAML silently keeps the last one)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from copilot_ray.sweep_spec.errors import SpecError


class SpecLoader(yaml.SafeLoader):
    """SafeLoader + `1e-3` is a float (YAML 1.1 reads it as a string) + duplicate keys are errors."""

    def construct_mapping(self, node, deep=False):  # noqa: ANN001 - PyYAML's signature
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                mark = key_node.start_mark
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first at line {seen[key] + 1})", mark
                )
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


SpecLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+][0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml_value(text: str) -> Any:
    """One value written as in a spec (YAML, with ``1e-3`` read as a float, as a reader expects)."""
    return yaml.load(text, Loader=SpecLoader)  # noqa: S506 - a SafeLoader subclass


def read_yaml_file(path: str | Path) -> Any:
    """The parsed contents of a spec file; raises SpecError naming the file (and line, for syntax)."""
    documents = read_yaml_documents(path)
    if len(documents) != 1:
        raise SpecError([f"{path}: expected one YAML document, found {len(documents)}"])
    return documents[0]


def read_yaml_documents(path: str | Path) -> list[Any]:
    """Every YAML document of a file (``---`` separates them; empty ones are skipped); raises SpecError
    naming the file (and line, for syntax)."""
    source = str(path)
    try:
        text = Path(path).read_text()
    except OSError as err:
        raise SpecError([f"{source}: cannot read the spec: {err.strerror or err}"]) from None
    try:
        docs = yaml.load_all(text, Loader=SpecLoader)  # noqa: S506 - a SafeLoader subclass
        return [doc for doc in docs if doc is not None] or [None]
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark is not None else source
        problem = getattr(err, "problem", None) or str(err)
        raise SpecError([f"{where}: YAML syntax error: {problem}"]) from None
