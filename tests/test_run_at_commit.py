"""scripts/run_at_commit.sh refuses bad arguments before it creates a worktree or installs anything."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "run_at_commit.sh"


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SCRIPT), *args], capture_output=True, text=True, timeout=60, cwd=ROOT)


def _worktrees() -> str:
    return subprocess.run(["git", "worktree", "list"], capture_output=True, text=True, cwd=ROOT).stdout


IN_GIT = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, cwd=ROOT).returncode == 0


@pytest.mark.skipif(not IN_GIT, reason="a git checkout: the script pins a commit")
def test_bad_arguments_exit_2_naming_them_and_create_no_worktree(tmp_path):
    before = _worktrees()
    missing = tmp_path / "nowhere.tar.gz"
    cases = {
        (): "usage: bash scripts/run_at_commit.sh",
        ("--carry", str(missing), "sweeps/smoke.yaml"): f"--carry {missing} is not a file",
        ("--commit", "no-such-rev", "sweeps/smoke.yaml"): "--commit no-such-rev is not a commit",
        ("--commit", "HEAD~0", "sweeps/no_such_spec.yaml"): "sweeps/no_such_spec.yaml is not in commit",
    }
    for args, message in cases.items():
        done = _run(*args)
        assert done.returncode == 2 and message in done.stderr, (args, done.stderr)
    assert _worktrees() == before
