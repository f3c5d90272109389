"""The GPU machine's imports, here: with this folder on PYTHONPATH and DEVICE_IMPORT_GUARD set, every
Python process (Ray's workers too: they inherit PYTHONPATH) may import only what that machine will have:
the standard library, this checkout's own modules, the distributions its image holds (packages.txt
beside this file, read off the device tool's KINDS.md) and the wheels that travel with the call
(scripts/device_wheels.json, written by scripts/gather_device_wheels.sh).

    DEVICE_IMPORT_GUARD=enforce   an import of anything else fails as it would there (ModuleNotFoundError)
    DEVICE_IMPORT_GUARD=record    it goes through, and is only written down
    DEVICE_IMPORT_LOG=FILE        one line per such import (mode, distribution, module, process): appended
    DEVICE_IMPORT_ALLOW=a,b       distributions allowed besides (to find what a wheel set lacks, one by one)

`scripts/device_check.sh` sets it when torch sees no CUDA device (a rehearsal). The versions here are not
the image's (torch 2.13 CPU here, 2.11 CUDA there; Python 3.11 here, 3.12 there): the guard checks which
packages a run needs, not their versions. Standard library only: it runs before anything else imports.
"""

from __future__ import annotations

import json
import os
import re
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))
_REPO = os.path.dirname(os.path.dirname(_HERE))
# Helpers that packaging tools install as top-level modules of no distribution of their own.
_NO_DISTRIBUTION = {"_distutils_hack", "sitecustomize", "usercustomize", "_virtualenv"}
# The standard library's own folder (its generated modules, e.g. _sysconfigdata_*, are in no list).
_STDLIB = os.path.dirname(os.__file__)


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def allowed_distributions(repo: str = _REPO) -> set[str]:
    """The image's distributions and the carried wheels' (normalised names)."""
    names = set()
    with open(os.path.join(repo, "scripts", "device_image", "packages.txt")) as f:
        names |= {_normal(line.strip()) for line in f if line.strip() and not line.startswith("#")}
    manifest = os.path.join(repo, "scripts", "device_wheels.json")
    if os.path.isfile(manifest):
        with open(manifest) as f:
            names |= {_normal(w["file"].split("-")[0]) for w in json.load(f)["wheels"]}
    return names


def _inside(path: str, folder: str) -> bool:
    return os.path.abspath(path).startswith(folder + os.sep)


class DeviceImportGuard:
    """A meta path finder that looks at each top-level module once, before the others find it."""

    def __init__(self, mode: str, log: str | None, allowed: set[str]):
        self.mode, self.log, self.allowed = mode, log, allowed
        self.seen: set[str] = set()
        self._dists: dict[str, list[str]] | None = None

    def find_spec(self, name, path=None, target=None):
        if "." in name or name in self.seen:
            return None
        self.seen.add(name)
        if name in sys.stdlib_module_names or name in sys.builtin_module_names or name in _NO_DISTRIBUTION:
            return None
        if name.startswith("__editable__"):  # an editable install's finder (this checkout)
            return None
        dists = self._distributions(name)
        if dists is None:  # no distribution: this checkout's own module, or nothing (a failed import)
            return None
        if any(_normal(d) in self.allowed or _normal(d) == "copilot-ray" for d in dists):
            return None
        self._write(name, dists)
        if self.mode == "enforce":
            raise ModuleNotFoundError(
                f"No module named {name!r} (on the GPU machine: {', '.join(dists)} is neither in its image "
                "nor among the carried wheels; scripts/device_image/sitecustomize.py)",
                name=name,
            )
        return None

    def _distributions(self, name: str) -> list[str] | None:
        if self._dists is None:
            from importlib import metadata

            self.seen.add("importlib")
            self._dists = metadata.packages_distributions()
        found = self._dists.get(name)
        if found:
            return found
        from importlib.machinery import PathFinder

        spec = PathFinder.find_spec(name)
        origin = getattr(spec, "origin", None) or ""
        locations = list(getattr(spec, "submodule_search_locations", None) or [])
        where = [p for p in [origin, *locations] if p]
        if spec is None or any(
            _inside(p, _REPO) or (_inside(p, _STDLIB) and "-packages" not in p) for p in where
        ):
            return None
        return [f"(no distribution: {where[0] if where else '?'})"]

    def _write(self, name: str, dists: list[str]) -> None:
        if not self.log:
            return
        line = f"{self.mode}\t{','.join(dists)}\t{name}\t{os.getpid()}\t{' '.join(sys.argv[:2])[:120]}\n"
        try:
            with open(self.log, "a") as f:
                f.write(line)
        except OSError:
            pass


def _install() -> None:
    mode = os.environ.get("DEVICE_IMPORT_GUARD", "")
    if mode not in ("enforce", "record"):
        return
    extra = {_normal(n) for n in os.environ.get("DEVICE_IMPORT_ALLOW", "").split(",") if n.strip()}
    allowed = allowed_distributions() | extra
    sys.meta_path.insert(0, DeviceImportGuard(mode, os.environ.get("DEVICE_IMPORT_LOG"), allowed))


_install()
