"""Every spec a benchmark writes passes the spec check (`python -m copilot_ray.sweep SPEC --check`), so a
new rule of the check cannot break a fault drill or a throughput measurement unseen. Nothing runs."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fault_drills  # noqa: E402
import throughput  # noqa: E402

from copilot_ray.sweep import main as sweep_main  # noqa: E402


def _check(path: Path, capsys) -> str:
    code = sweep_main([str(path), "--check"])
    out, err = capsys.readouterr()
    assert code == 0, f"{path.name} fails the spec check:\n{err}"
    return out


@pytest.mark.parametrize("drill", sorted(fault_drills.DRILL_SPECS))
def test_each_fault_drill_spec_passes_the_spec_check(drill, tmp_path, capsys):
    path = fault_drills.DRILL_SPECS[drill](tmp_path, iterations=6)
    out = _check(path, capsys)
    assert yaml.safe_load(path.read_text())["name"] in out


def test_the_drills_temp_folder_is_removed_and_a_kept_one_kept(tmp_path, monkeypatch, capsys):
    """Without --keep the drills' folder (~200 MB once they ran) is a new one in the temp folder, removed
    at the end, a failing drill's too, and its place said; --keep's is kept and said so."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the system's temp folder, here
    with pytest.raises(RuntimeError), fault_drills.work_folder(None) as directory:
        assert directory.parent == tmp_path and directory.is_dir()
        (directory / "results").mkdir()
        (directory / "results" / "mlflow.db").write_text("what a drill leaves")
        raise RuntimeError("a drill failed")
    assert list(tmp_path.iterdir()) == []
    assert capsys.readouterr().out == f"removed the drills' work folder {directory} (--keep DIR keeps one)\n"
    kept = tmp_path / "kept" / "drills"
    with fault_drills.work_folder(kept) as directory:
        assert directory == kept
        (directory / "drill.log").write_text("kept")
    assert (kept / "drill.log").read_text() == "kept"
    assert capsys.readouterr().out == f"kept the drills' work folder {kept}\n"


def test_every_fault_drill_has_its_spec():
    assert set(fault_drills.DRILL_SPECS) == set(fault_drills.DRILLS)


@pytest.mark.parametrize("algorithm", ["copilot", "sac"])
@pytest.mark.parametrize("n", [1, 2])
def test_the_throughput_benchmarks_specs_pass_the_spec_check(algorithm, n, tmp_path, capsys):
    args = throughput.parse_args(["--algorithms", algorithm])
    path = tmp_path / f"{algorithm}_n{n}.yaml"
    spec = throughput._spec(algorithm, n, args, cpus=max(1, 2 // n), store=tmp_path / "store.db")
    path.write_text(yaml.safe_dump(spec))
    assert spec["name"] in _check(path, capsys)
