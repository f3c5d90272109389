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


def _archive(path: Path, manifest: dict) -> Path:
    import io
    import json
    import tarfile

    data = json.dumps(manifest).encode()
    info = tarfile.TarInfo("results/carry.json")
    info.size = len(data)
    with tarfile.open(path, "w:gz") as tar:
        tar.addfile(info, io.BytesIO(data))
    return path


@pytest.mark.skipif(not IN_GIT, reason="a git checkout: the script pins a commit")
def test_a_carried_store_continues_only_at_its_commit_and_its_path(tmp_path):
    """An archive from `python -m copilot_ray.carry` names the commit and folder it was packed in: another
    commit (one experiment, one commit) or another path (Tune's state names absolute paths) is refused
    before any worktree is made."""
    before = _worktrees()
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=ROOT
    ).stdout.strip()
    tree = f"{ROOT.parent}/{ROOT.name}-at-{head[:7]}"
    other_commit = _archive(tmp_path / "a.tar.gz", {"root": tree, "commit": "0" * 40})
    done = _run("--commit", head, "--carry", str(other_commit), "sweeps/smoke.yaml")
    assert done.returncode == 2 and "packed at commit 0000000, not " + head[:7] in done.stderr, done.stderr
    other_root = _archive(tmp_path / "b.tar.gz", {"root": "/elsewhere/main-at-x", "commit": head})
    done = _run("--commit", head, "--carry", str(other_root), "sweeps/smoke.yaml")
    assert done.returncode == 2 and "was packed in /elsewhere/main-at-x" in done.stderr, done.stderr
    assert _worktrees() == before
