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


def _git(repo: Path, *args: str) -> str:
    done = subprocess.run(["git", *args], capture_output=True, text=True, cwd=repo, check=True)
    return done.stdout.strip()


# Stands in for scripts/setup_env.sh in a throwaway repository: a .venv whose python records how the
# sweep was started (from which folder, with which arguments) instead of running it.
FAKE_SETUP = """#!/usr/bin/env bash
set -e
cd "$(dirname "$0")/.."
mkdir -p .venv/bin
printf '#!/usr/bin/env bash\\necho "$PWD $*" > results/started.txt\\n' > .venv/bin/python
chmod +x .venv/bin/python
"""


@pytest.fixture()
def throwaway_repo(tmp_path):
    """A git repository holding the script, at two commits: the code's (sweeps/a.yaml) and a later one
    that adds sweeps/b.yaml and changes a.yaml."""
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    (repo / "sweeps").mkdir()
    (repo / "scripts" / "run_at_commit.sh").write_text(SCRIPT.read_text())
    (repo / "scripts" / "setup_env.sh").write_text(FAKE_SETUP)
    (repo / "sweeps" / "a.yaml").write_text("name: a\n")
    _git(repo, "init", "-q")
    _git(repo, "add", "-A")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "code")
    code = _git(repo, "rev-parse", "HEAD")
    (repo / "sweeps" / "b.yaml").write_text("name: b\nseeds: [2, 3, 4]\n")
    (repo / "sweeps" / "a.yaml").write_text("name: a changed\n")
    _git(repo, "add", "-A")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "a later part")
    return repo, code, _git(repo, "rev-parse", "HEAD")


def _run_in(repo: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", "scripts/run_at_commit.sh", *args], capture_output=True, text=True, timeout=60, cwd=repo
    )


def _wait_for(path: Path) -> str:
    import time

    for _ in range(100):
        if path.is_file() and path.read_text():
            return path.read_text()
        time.sleep(0.1)
    raise AssertionError(f"{path} never written")


def test_spec_from_runs_a_later_commits_part_with_the_code_of_the_pinned_commit(throwaway_repo):
    """A part added after the experiment began (seeds its rule asks for) runs with the code it began
    with: the worktree stays at the code's commit, the spec is the later commit's, and a copy there
    that was edited since is refused, so a resumed part keeps the spec it began with."""
    repo, code, later = throwaway_repo
    tree = repo.parent / f"repo-at-{code[:7]}"

    done = _run_in(repo, "--commit", code, "--spec-from", later, "sweeps/b.yaml", "--resume")
    assert done.returncode == 0, done.stderr
    assert f"sweeps/b.yaml from {later[:7]}" in done.stdout
    assert _git(tree, "rev-parse", "HEAD") == code
    assert (tree / "sweeps" / "b.yaml").read_text() == "name: b\nseeds: [2, 3, 4]\n"
    assert _wait_for(tree / "results" / "started.txt").split() == [
        str(tree),
        "-m",
        "copilot_ray.sweep",
        "sweeps/b.yaml",
        "--resume",
    ]

    (tree / "sweeps" / "b.yaml").write_text("name: b\nseeds: [2]\n")
    done = _run_in(repo, "--commit", code, "--spec-from", later, "sweeps/b.yaml", "--resume")
    assert (
        done.returncode == 2
        and f"{tree}/sweeps/b.yaml differs from sweeps/b.yaml in {later[:7]}" in done.stderr
        and "resume with --spec-from" not in done.stderr
    )
    # A later commit that edits the spec (a comment, say) is refused too, and the error names the
    # commit whose spec the part began with.
    (tree / "sweeps" / "b.yaml").write_text("name: b\nseeds: [2, 3, 4]\n")
    (repo / "sweeps" / "b.yaml").write_text("# a comment\nname: b\nseeds: [2, 3, 4]\n")
    _git(repo, "add", "-A")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "comment")
    done = _run_in(repo, "--commit", code, "--spec-from", "HEAD", "sweeps/b.yaml", "--resume")
    assert done.returncode == 2 and f"resume with --spec-from {later[:7]}" in done.stderr

    # A spec the code's commit holds in another version would leave the worktree's tracked file edited.
    done = _run_in(repo, "--commit", code, "--spec-from", later, "sweeps/a.yaml")
    assert done.returncode == 2 and f"commit {code[:7]} holds another sweeps/a.yaml" in done.stderr
    done = _run_in(repo, "--commit", code, "--spec-from", "no-such-rev", "sweeps/b.yaml")
    assert done.returncode == 2 and "--spec-from no-such-rev is not a commit" in done.stderr
    # Edited and not committed: the committed version would run, not the one the user sees.
    (repo / "sweeps" / "b.yaml").write_text("name: b\nseeds: [9]\n")
    done = _run_in(repo, "--commit", code, "--spec-from", "HEAD", "sweeps/b.yaml")
    assert done.returncode == 2 and "sweeps/b.yaml has uncommitted changes" in done.stderr


def test_a_second_carried_store_unpacks_beside_the_first_and_never_overwrites(throwaway_repo, tmp_path):
    """Two sweep files of one worktree (the comparison and a part added to it, each with its own SQLite
    store) are carried as two archives (gzip and xz): the second unpacks beside the first; one holding a
    file that is there already is refused before anything is unpacked."""
    import io
    import json
    import tarfile

    repo, code, _ = throwaway_repo
    tree = repo.parent / f"repo-at-{code[:7]}"

    def archive(name: str, files: dict[str, str]) -> Path:
        path = tmp_path / name
        with tarfile.open(path, "w:xz" if name.endswith(".xz") else "w:gz") as tar:
            members = {**files, "results/carry.json": json.dumps({"root": str(tree), "commit": code})}
            for arcname, text in members.items():
                info = tarfile.TarInfo(arcname)
                info.size = len(text.encode())
                tar.addfile(info, io.BytesIO(text.encode()))
        return path

    first = archive("first.tar.gz", {"results/first.db": "one"})
    second = archive("second.tar.xz", {"results/second.db": "two"})  # `carry`'s smaller kind: read alike
    assert _run_in(repo, "--commit", code, "--carry", str(first), "sweeps/a.yaml", "--resume").returncode == 0
    _wait_for(tree / "results" / "started.txt")
    (tree / "results" / "first.db").write_text("one, grown since")
    done = _run_in(repo, "--commit", code, "--carry", str(second), "sweeps/a.yaml", "--resume")
    assert done.returncode == 0, done.stderr
    assert (tree / "results" / "second.db").read_text() == "two"
    done = _run_in(repo, "--commit", code, "--carry", str(first), "sweeps/a.yaml", "--resume")
    assert done.returncode == 2 and f"would overwrite {tree}/results/first.db" in done.stderr
    assert (tree / "results" / "first.db").read_text() == "one, grown since"
