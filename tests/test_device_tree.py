"""scripts/device_tree.py: what a call of the GPU machine carries fits its 64 MiB once docs/' results are
parked (this checkout, the wheels counted from their manifest where not gathered); park and unpark move
them out of the working tree and back, leaving git's view unchanged; above the limit `size` exits 1."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("device_tree", ROOT / "scripts" / "device_tree.py")
device_tree = importlib.util.module_from_spec(_spec)
sys.modules["device_tree"] = device_tree
_spec.loader.exec_module(device_tree)


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True, text=True).stdout


def test_this_checkout_fits_the_call_once_its_results_are_parked(capsys):
    """The suite's guard: the wheels (gathered or from the manifest) plus everything else that travels."""
    assert device_tree.main(["size", "--if-parked", "--top", "3"]) == 0
    out = capsys.readouterr().out
    assert "of the call's 64 MiB: fits" in out
    entries, _ = device_tree.travelling(ROOT, ["device_wheels"], if_parked=True)
    assert sum(e.size for e in entries) <= device_tree.LIMIT
    assert any(e.path.startswith("device_wheels/ray-") for e in entries)  # the wheels are counted


def test_the_parked_folder_is_ignored_so_it_never_travels():
    assert _git(ROOT, "check-ignore", ".parked/docs/x/store.tar.gz").strip() == ".parked/docs/x/store.tar.gz"


def test_the_wheels_manifest_holds_every_requirement_of_the_gather_script():
    script = (ROOT / "scripts" / "gather_device_wheels.sh").read_text()
    block = script.split("wheels=(", 1)[1].split("\n)", 1)[0]
    wanted = [line.strip().strip('"') for line in block.splitlines() if line.strip().startswith('"')]
    manifest = device_tree.wheels_manifest(ROOT)
    assert manifest["requirements"] == wanted, "run scripts/gather_device_wheels.sh: its manifest is stale"

    def norm(s: str) -> str:
        return re.sub(r"[-_.]+", "-", s).lower()

    files = {norm(w["file"].split("-")[0]): w["file"].split("-")[1] for w in manifest["wheels"]}
    for requirement in wanted:
        name, _, version = requirement.partition("==")
        assert norm(name) in files, requirement
        assert not version or files[norm(name)] == version, requirement
    assert manifest["total_bytes"] == sum(w["bytes"] for w in manifest["wheels"])


@pytest.mark.parametrize(
    "path, size, parked",
    [
        ("docs/privilege_matched/store.tar.gz", 10, True),
        ("docs/fair_maze/report/diagnostics.png", 10, True),
        ("docs/fair_maze/report/metrics.csv.gz", 10, True),
        ("docs/fair_maze/README.md", 10, False),
        ("docs/fair_maze/huge.md", 300 * 1024, True),
        ("copilot_ray/measured_throughput.json", 300 * 1024, False),
        ("tests/figure.png", 10, False),
    ],
)
def test_what_is_parked(path, size, parked):
    assert device_tree.parkable(path, size) is parked


def _repo(tmp_path: Path) -> Path:
    repo = tmp_path / "repo"
    (repo / "docs" / "exp" / "report").mkdir(parents=True)
    (repo / "scripts").mkdir()
    (repo / ".gitignore").write_text("/.parked/\n/device_wheels/\n")
    (repo / "code.py").write_text("print('hi')\n")
    (repo / "docs" / "exp" / "README.md").write_text("# results\n")
    (repo / "docs" / "exp" / "store.tar.gz").write_bytes(b"\x1f\x8b" + bytes(range(256)) * 40)
    (repo / "docs" / "exp" / "report" / "figure.png").write_bytes(b"\x89PNG" + b"x" * 5000)
    _git(repo.parent, "init", "-q", str(repo))
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "start")
    (repo / "docs" / "exp" / "new_store.tar.gz").write_bytes(b"not committed yet")  # untracked: travels too
    return repo


def test_park_leaves_the_results_behind_and_unpark_puts_them_back_as_they_were(tmp_path, capsys):
    repo = _repo(tmp_path)
    before = {p: (repo / p).read_bytes() for p in _git(repo, "ls-files").split()}
    as_is, _ = device_tree.travelling(repo, [])
    assert {e.path for e in as_is} >= {"docs/exp/store.tar.gz", "docs/exp/new_store.tar.gz"}

    assert device_tree.main(["--root", str(repo), "park"]) == 0
    assert not (repo / "docs" / "exp" / "store.tar.gz").exists()
    assert not (repo / "docs" / "exp" / "report").exists()  # an emptied folder goes too
    assert (repo / ".parked" / "docs" / "exp" / "store.tar.gz").is_file()
    assert (repo / "docs" / "exp" / "README.md").is_file()  # text stays
    parked, _ = device_tree.travelling(repo, [])
    assert {e.path for e in parked} == {".gitignore", "code.py", "docs/exp/README.md"}
    # git sees nothing changed: a commit -a now cannot record the parked files as deleted
    assert _git(repo, "status", "--porcelain") == ""
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "nothing", "--allow-empty")
    assert "docs/exp/store.tar.gz" in _git(repo, "ls-files")
    assert device_tree.main(["--root", str(repo), "park"]) == 0  # again: nothing more to move
    assert "parked 0 files" in capsys.readouterr().out.splitlines()[-1]

    assert device_tree.main(["--root", str(repo), "unpark"]) == 0
    assert {p: (repo / p).read_bytes() for p in before} == before
    assert (repo / "docs" / "exp" / "new_store.tar.gz").read_bytes() == b"not committed yet"
    assert not (repo / ".parked").exists()
    assert not [line for line in _git(repo, "ls-files", "-v").splitlines() if line.startswith("S ")]
    assert _git(repo, "status", "--porcelain") == "?? docs/exp/new_store.tar.gz\n"


def test_unpark_keeps_both_copies_of_a_file_that_came_back_different(tmp_path, capsys):
    repo = _repo(tmp_path)
    assert device_tree.main(["--root", str(repo), "park"]) == 0
    (repo / "docs" / "exp" / "store.tar.gz").write_bytes(b"another version")
    assert device_tree.main(["--root", str(repo), "unpark"]) == 1
    assert "docs/exp/store.tar.gz is back in its place and differs" in capsys.readouterr().err
    assert (repo / ".parked" / "docs" / "exp" / "store.tar.gz").is_file()
    assert [f["path"] for f in device_tree.parked_entries(repo)] == ["docs/exp/store.tar.gz"]
    assert (repo / "docs" / "exp" / "report" / "figure.png").is_file()  # the others went back


def test_size_exits_1_above_the_limit_and_says_what_park_would_leave(tmp_path, monkeypatch, capsys):
    repo = _repo(tmp_path)
    monkeypatch.setattr(device_tree, "LIMIT", 4096)
    assert device_tree.main(["--root", str(repo), "size", "--carry"]) == 1
    out = capsys.readouterr().out
    assert "OVER by" in out and "`python3 scripts/device_tree.py park` leaves" in out
    assert device_tree.main(["--root", str(repo), "size", "--carry", "--if-parked"]) == 0


def test_carried_paths_count_and_absent_wheels_come_from_the_manifest(tmp_path, capsys):
    repo = _repo(tmp_path)
    (repo / "scripts" / "device_wheels.json").write_text(
        '{"requirements": ["x"], "wheels": [{"file": "x-1-py3-none-any.whl", "bytes": 3000000}], '
        '"total_bytes": 3000000}\n'
    )
    (repo / ".venv_bits").mkdir()
    (repo / ".venv_bits" / "blob").write_bytes(b"y" * 1000)
    entries, notes = device_tree.travelling(repo, ["device_wheels", ".venv_bits", "missing"])
    sizes = {e.path: (e.size, e.source) for e in entries}
    assert sizes["device_wheels/x-1-py3-none-any.whl"] == (3000000, "manifest")
    assert sizes[".venv_bits/blob"] == (1000, "carry")
    assert any("not gathered here" in n for n in notes) and any("--carry missing" in n for n in notes)
    (repo / "device_wheels").mkdir()
    (repo / "device_wheels" / "x-1-py3-none-any.whl").write_bytes(b"w" * 10)
    entries, notes = device_tree.travelling(repo, ["device_wheels"])
    assert {e.path: e.size for e in entries}["device_wheels/x-1-py3-none-any.whl"] == 10  # the real file
    assert not notes
