"""Every public module imports on its own, first, in a fresh interpreter (no hidden import-order cycles)."""

import subprocess
import sys

import pytest

MODULES = [
    "copilot_ray.evaluation",  # was a cycle: evaluation -> copilot package -> algorithm -> evaluation
    "copilot_ray.algorithms.sac.traversal_env",
    "copilot_ray.algorithms.copilot.algorithm",
    "copilot_ray.algorithms.gc_sac",
    "analysis.report",
]


@pytest.mark.parametrize("module", MODULES)
def test_module_imports_first(module):
    done = subprocess.run(
        [sys.executable, "-c", f"import {module}"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
