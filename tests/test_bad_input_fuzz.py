"""Bad input, generated: malformed sweep specs and layout files (Hypothesis). Every one is refused with the
project's own error (SpecError / LayoutError), one line per problem naming the key path or the line, never
another exception; the CLI exits 2 before Ray is imported."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from copilot_ray.envs.maze.layouts import LayoutError, parse_layout
from copilot_ray.sweep_spec import SpecError, parse_spec

ROOT = Path(__file__).resolve().parents[1]
BASE = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
BASE["tracking"] = {"storage": "/tmp/copilot_ray_fuzz_never_written"}  # parse_spec only resolves it

# Values of the wrong kind for any key: every spec field and setting has a type these break somewhere.
JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**6), max_value=10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8),
    st.lists(st.integers(-3, 3), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(-3, 3), max_size=2),
)

# (path in the spec, whether any value breaks it): where a mutation lands.
PATHS = [
    ("name",),
    ("env", "id"),
    ("env", "config", "layout"),
    ("env", "config", "speed"),
    ("algorithm",),
    ("config", "repetitions"),
    ("config", "tau_max"),
    ("config", "task_batch_size"),
    ("config", "planner.std"),
    ("config", "alpha_schedule"),
    ("search", "tree_depth"),
    ("search", "tree_depth", "grid"),
    ("seeds",),
    ("searcher", "type"),
    ("searcher", "metric"),
    ("stop", "env_steps"),
    ("stop", "iterations"),
    ("resources", "max_concurrent_trials"),
    ("resources", "num_env_runners"),
    ("variants",),
]


def _set(spec: dict, path: tuple[str, ...], value) -> dict:
    node = spec
    for part in path[:-1]:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[path[-1]] = value
    return spec


def _check_refusal(spec: dict) -> None:
    """Either the spec is valid, or parse_spec raises SpecError whose lines each name a key path."""
    try:
        parse_spec(spec, "<fuzz>")
    except SpecError as err:
        assert err.problems, "a SpecError with no problem lines"
        for line in err.problems:
            assert line.startswith("<fuzz>"), line
            assert ": " in line[len("<fuzz>") :], line  # "<fuzz>: <key path>: <value> is invalid: ..."


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutations=st.lists(st.tuples(st.sampled_from(PATHS), JUNK), min_size=1, max_size=3))
def test_a_spec_with_junk_values_is_refused_with_spec_errors_only(mutations):
    spec = copy.deepcopy(BASE)
    for path, value in mutations:
        _set(spec, path, value)
    _check_refusal(spec)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    drop=st.sets(st.sampled_from(sorted(BASE)), max_size=3),
    extra=st.dictionaries(st.text(min_size=1, max_size=6), JUNK, max_size=2),
)
def test_a_spec_with_missing_or_unknown_keys_is_refused_naming_them(drop, extra):
    spec = {k: copy.deepcopy(v) for k, v in BASE.items() if k not in drop}
    unknown = {k: v for k, v in extra.items() if k not in BASE}
    spec.update(unknown)
    try:
        parse_spec(spec, "<fuzz>")
    except SpecError as err:
        text = "\n".join(err.problems)
        for key in set(drop) & {"name", "env", "stop"}:  # required keys
            assert f"<fuzz>: {key}: required key is missing" in text
        for key in unknown:
            assert repr(key)[1:-1] in text or key in text
    else:
        assert not (set(drop) & {"name", "env", "stop"}) and not unknown


@settings(max_examples=150, deadline=None)
@given(rows=st.lists(st.text(alphabet=".#x \t", max_size=12), max_size=8))
def test_a_layout_file_is_parsed_or_refused_naming_its_line(rows):
    text = "\n".join(rows)
    try:
        layout = parse_layout(text, source="fuzz.txt")
    except LayoutError as err:
        assert str(err).startswith("fuzz.txt:") and err.line >= 1 and err.column >= 1
    else:
        assert layout.grid.shape[0] >= 1 and layout.grid.shape[1] >= 1


@pytest.mark.parametrize(
    "mutation",
    [
        {"stop": {"env_steps": -5}},
        {"env": {"id": "maze-pont"}},
        {"config": {"repetitions": "5"}},
        {"resources": {"max_concurrent_trials": 0}},
    ],
)
def test_the_cli_exits_2_without_importing_ray(tmp_path, mutation):
    spec = {**copy.deepcopy(BASE), **mutation}
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(spec))
    code = (
        "import sys; from copilot_ray.sweep import main; rc = main([sys.argv[1]]); "
        "print('RAY_IMPORTED' if 'ray' in sys.modules else 'NO_RAY'); raise SystemExit(rc)"
    )
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "NO_RAY" in out.stdout and "Traceback" not in out.stderr
    assert out.stderr.strip().startswith(str(path))
