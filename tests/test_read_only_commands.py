"""The commands that only read a store (`analysis.report`, `copilot_ray.stages`, `copilot_ray.progress`)
refuse a SQLite store file that does not exist, naming its path, with exit status 2, and create nothing:
MLflow would otherwise create an empty store in its place and then say the experiment is missing."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from analysis import report
from copilot_ray import progress, stages

ROOT = Path(__file__).resolve().parents[1]


def _nothing_created(folder: Path) -> None:
    assert sorted(p.name for p in folder.iterdir()) == ["work"]
    assert not any((folder / "work").iterdir())


@pytest.fixture
def cwd(tmp_path, monkeypatch) -> Path:
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    return tmp_path


@pytest.mark.parametrize(
    "command",
    [
        lambda uri: report.main(["smoke", "--tracking-uri", uri]),
        lambda uri: report.main(["smoke", "--tracking-uri", uri, "--also-from", uri]),
        lambda uri: stages.main(["smoke", "--tracking-uri", uri]),
    ],
    ids=["report", "report --also-from", "stages"],
)
def test_a_missing_store_file_is_refused_by_name_and_not_created(command, cwd, capsys):
    missing = cwd / "typo" / "mlflow.db"
    assert command(f"sqlite:///{missing}") == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "no store file" in err and len(err.strip().splitlines()) == 1
    _nothing_created(cwd)


def test_the_report_refuses_a_missing_store_named_by_the_environment(cwd, monkeypatch, capsys):
    missing = cwd / "elsewhere.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{missing}")
    assert report.main(["smoke"]) == 2
    assert f"MLFLOW_TRACKING_URI 'sqlite:///{missing}' is invalid" in capsys.readouterr().err
    _nothing_created(cwd)


def test_the_report_names_an_existing_folder_given_for_a_store_file(cwd, capsys):
    assert report.main(["smoke", "--tracking-uri", f"sqlite:///{cwd}"]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_progress_refuses_a_file_whose_store_does_not_exist(cwd, capsys):
    spec = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    spec["tracking"] = {"storage": "results"}
    (cwd / "work" / "smoke.yaml").write_text(yaml.safe_dump(spec))
    assert progress.main(["smoke.yaml", "--root", str(cwd / "work")]) == 2
    err = capsys.readouterr().err
    assert str(cwd / "work" / "results" / "smoke" / "mlflow.db") in err and "no store file" in err
    assert sorted(p.name for p in (cwd / "work").iterdir()) == ["smoke.yaml"]
