"""The package's import graph has no cycles and keeps the layers ARCHITECTURE.md states.

Every `import` / `from ... import` of a `copilot_ray` module counts, at module level or inside a
function (a function-level import that closes a cycle is the same cycle, only hidden). The layer table
is read from ARCHITECTURE.md itself, so the document and the code cannot drift apart.
"""

from __future__ import annotations

import ast
import fnmatch
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("copilot_ray", "analysis")


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """The package modules `name` imports (`from a import b` is a.b when that is a module, else a)."""
    is_package = path.name == "__init__.py"
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            targets = [f"{module}.{alias.name}" for alias in node.names if f"{module}.{alias.name}" in known]
            targets = targets or [module]
        else:
            continue
        out.update(t for t in targets if t in known and t != name)
    return out


def import_graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports_of(name, path, known) for name, path in mods.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_graph_sees_known_edges():
    graph = import_graph()
    assert "copilot_ray.algorithms.copilot.settings" in graph["copilot_ray.algorithms.copilot.algorithm"]
    assert "copilot_ray.algorithms.sac.algorithm" in graph["copilot_ray.algorithms.copilot.algorithm"]


def test_a_planted_cycle_is_found():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]


def test_no_import_cycles():
    assert cycles(import_graph()) == []


# ----------------------------------------------------------------------------- ARCHITECTURE's table
_ROW = re.compile(r"^    (\d+|side)\s{2,}(.+?)\s{2,}(.+)$")


def stated_layers() -> tuple[list[tuple[int, list[str], str]], list[str]]:
    """([(layer, module patterns, what else it may use)], the side layer's allowed imports) from the
    table under "Layers" in ARCHITECTURE.md."""
    text = (ROOT / "ARCHITECTURE.md").read_text()
    section = text.split("### Layers: what imports what", 1)[1].split("\n###", 1)[0]
    layers, side = [], []
    for line in section.splitlines():
        m = _ROW.match(line)
        if not m:
            continue
        if m.group(1) == "side":
            side = [p.strip() for p in m.group(2).split(":", 1)[1].split(",")]
        else:
            layers.append((int(m.group(1)), [p.strip() for p in m.group(2).split(",")], m.group(3)))
    return layers, side


def _matches(module: str, pattern: str) -> bool:
    """`algorithms/*/trial` names copilot_ray.algorithms.<x>.trial; `envs`: the package and below."""
    dotted = "copilot_ray." + pattern.replace("/", ".")
    return fnmatch.fnmatchcase(module, dotted) or fnmatch.fnmatchcase(module, dotted + ".*")


def layer_of(module: str, layers) -> int | None:
    """The layer of the most specific pattern naming `module` (the longest one)."""
    best = None
    for number, patterns, _ in layers:
        for pattern in patterns:
            if _matches(module, pattern) and (best is None or len(pattern) > best[1]):
                best = (number, len(pattern))
    return None if best is None else best[0]


def layer_violations(graph: dict[str, set[str]], layers, side: list[str]) -> list[str]:
    out = []
    for module, deps in sorted(graph.items()):
        if module.startswith("analysis"):
            bad = sorted(
                d for d in deps if d.startswith("copilot_ray") and not any(_matches(d, p) for p in side)
            )
            out += [f"{module} (analysis) imports {d}" for d in bad]
            continue
        if module == "copilot_ray":
            continue
        own = layer_of(module, layers)
        if own is None:
            out.append(f"{module} is in no layer of ARCHITECTURE.md's table")
            continue
        for dep in sorted(deps):
            theirs = layer_of(dep, layers)
            if theirs is not None and theirs > own:
                out.append(f"{module} (layer {own}) imports {dep} (layer {theirs})")
    return out


def imports_ray_when_imported(path: Path) -> bool:
    """Whether importing the module imports Ray (module-level statements; a function may import it
    when called: `sweep_spec.tune_translation` builds Tune objects only for a run)."""
    for node in _module_level(ast.parse(path.read_text()).body):
        names = (
            [a.name for a in node.names]
            if isinstance(node, ast.Import)
            else [node.module or ""]
            if isinstance(node, ast.ImportFrom) and not node.level
            else []
        )
        if any(n == "ray" or n.startswith("ray.") for n in names):
            return True
    return False


def _module_level(body: list[ast.stmt]):
    for node in body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        yield node
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.stmt):
                yield from _module_level([child])


def test_the_table_is_read_and_names_every_layer():
    layers, side = stated_layers()
    assert [n for n, _, _ in layers] == list(range(1, len(layers) + 1)) and len(layers) >= 10
    assert layer_of("copilot_ray.algorithms.copilot.settings", layers) < layer_of(
        "copilot_ray.algorithms.copilot.algorithm", layers
    )
    assert layer_of("copilot_ray.algorithms.sac.trial", layers) > layer_of("copilot_ray.algorithms", layers)
    assert "keys" in side


def test_a_planted_upward_import_is_reported():
    layers, side = stated_layers()
    graph = {
        "copilot_ray.envs.maze.env": {"copilot_ray.algorithms.copilot.algorithm"},
        "copilot_ray.sweep_spec.models": {"copilot_ray.keys"},
        "analysis.report": {"copilot_ray.tracking"},
    }
    assert layer_violations(graph, layers, side) == [
        "analysis.report (analysis) imports copilot_ray.tracking",
        "copilot_ray.envs.maze.env (layer 2) imports copilot_ray.algorithms.copilot.algorithm (layer 9)",
    ]


def test_every_module_keeps_the_stated_layers():
    layers, side = stated_layers()
    assert layer_violations(import_graph(), layers, side) == []


def test_the_layers_stated_without_ray_never_import_it():
    layers, _ = stated_layers()
    ray_free = [n for n, _, uses in layers if "no Ray" in uses] + [1]
    for module, path in modules().items():
        if module.startswith("analysis") or layer_of(module, layers) in ray_free:
            assert not imports_ray_when_imported(path), (
                f"{module} imports Ray (ARCHITECTURE.md: no Ray in its layer)"
            )
