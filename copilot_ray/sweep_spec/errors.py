"""What a spec validation reports: one line per problem, naming the file, the key path and the value."""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Any


class SpecError(ValueError):
    """A spec that cannot run. ``str(err)`` is one line per problem: ``file: key.path: value is invalid: why``."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


class Issue(ValueError):
    """One problem found by a validator: path relative to where pydantic raised it (or absolute)."""

    def __init__(self, path: str, value: Any, reason: str, *, show_value: bool = True):
        self.path, self.value, self.reason, self.show_value = path, value, reason, show_value
        super().__init__(self.text())

    def text(self, prefix: str = "") -> str:
        path = join_path(prefix, self.path)
        head = f"{path}: " if path else ""
        if self.show_value:
            return f"{head}{short(self.value)} is invalid: {self.reason}"
        return f"{head}{self.reason}"


class Issues(ValueError):
    def __init__(self, issues: list[Issue]):
        self.issues = issues
        super().__init__("; ".join(i.text() for i in issues))


def join_path(prefix: str, path: str) -> str:
    if not prefix:
        return path
    if not path:
        return prefix
    return prefix + path if path.startswith("[") else f"{prefix}.{path}"


def short(value: Any, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def did_you_mean(word: str, known: Iterable[str]) -> str:
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""
