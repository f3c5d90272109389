"""`python -m copilot_ray.carry` packs what --resume needs on another machine: the store (a snapshot), the
parts' folders, the Tune folders of unfinished parts only, no final checkpoints unless asked; unpacked in
place, --resume skips the finished part and continues the unfinished one through Tune. (A real sweep cut
mid-trial, carried and resumed through Tune: tests/test_sweep.py, where the smoke sweep's resume is.)"""

from __future__ import annotations

import json
import shutil
import sqlite3
import tarfile
from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

from copilot_ray import carry, sweep, tracking
from copilot_ray.keys import PARENT_TAG, ROLE_TAG, ROLE_TRIAL, SWEEP_TAG
from copilot_ray.sweep_spec import load_specs
from tests import stores

ROOT = Path(__file__).resolve().parents[1]


def _three_parts(tmp_path: Path):
    """A spec file of three parts with a store: `done` finished, `cut` interrupted with its Tune folder,
    `fresh` never started; each started part has a Tune checkpoint and a run with a final checkpoint."""
    uri = f"sqlite:///{tmp_path}/results/carried.db"
    base = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    base["tracking"] = {"storage": str(tmp_path / "results"), "uri": uri}
    path = tmp_path / "three.yaml"
    parts = [{**base, "name": name} for name in ("done", "cut", "fresh")]
    path.write_text("---\n".join(yaml.safe_dump(p, sort_keys=False) for p in parts))
    (tmp_path / "results").mkdir()
    done, cut, fresh = load_specs(path)
    _, parent, _ = tracking.open_sweep_run(uri, done.experiment, done.name, resume=False)
    tracking.end_sweep_run(uri, parent, "FINISHED")
    _, cut_parent, _ = tracking.open_sweep_run(uri, cut.experiment, cut.name, resume=False)
    client = tracking._client(uri)
    exp_id = client.get_experiment_by_name(cut.experiment).experiment_id
    client.create_run(exp_id, tags={SWEEP_TAG: cut.name, ROLE_TAG: ROLE_TRIAL, PARENT_TAG: cut_parent})
    for spec in (done, cut):
        folder = tmp_path / "results" / spec.name
        checkpoint = folder / "tune" / sweep.experiment_names(spec)[0][0] / "trial_1" / "checkpoint_000002"
        checkpoint.mkdir(parents=True)
        (checkpoint / "state.pkl").write_bytes(b"weights")
        artifacts = folder / "mlartifacts" / "run1" / "artifacts"
        (artifacts / "checkpoint").mkdir(parents=True)
        (artifacts / "checkpoint" / "algorithm_state.pkl").write_bytes(b"final")
        (artifacts / "config.yaml").write_text("trial: {}\n")
        (folder / "optuna.db").write_bytes(b"studies")
    # a trial of the cut part that finished before the cut: its checkpoints stay behind
    finished = tmp_path / "results" / cut.name / "tune" / sweep.experiment_names(cut)[0][0] / "trial_0"
    (finished / "checkpoint_000003").mkdir(parents=True)
    (finished / "checkpoint_000003" / "state.pkl").write_bytes(b"weights")
    (finished / "result.json").write_text('{"done": false}\n{"done": true}\n')
    # Tune's states of two runs of the cut part (a resumed sweep writes one per run) and a TensorBoard log
    experiment = finished.parent
    for stamp in ("2026-12-01_10-00-00", "2026-12-02_10-00-00"):
        (experiment / f"experiment_state-{stamp}.json").write_text('{"trial_data": []}')
        (experiment / f"basic-variant-state-{stamp}.json").write_text("{}")
    (experiment / "trial_1" / "events.out.tfevents.1796179652.vm").write_bytes(b"scalars")
    (tmp_path / "results" / "three.log").write_text("=== part 1 of 3\n")
    return path, uri, (done, cut, fresh)


def _names(archive: Path) -> set[str]:
    with tarfile.open(archive) as tar:
        return set(tar.getnames())


def test_pack_keeps_the_store_and_unfinished_tune_folders_and_leaves_out_the_rest(tmp_path):
    path, uri, _ = _three_parts(tmp_path)
    out = tmp_path / "carried.tar.gz"
    states = carry.pack(path, out, tmp_path)
    assert [(s.name, s.label) for s in states] == [
        ("done", "finished"),
        ("cut", "unfinished"),
        ("fresh", "not started"),
    ]
    names = _names(out)
    assert "results/carried.db" in names and "results/three.log" in names
    assert "results/cut/tune/cut/trial_1/checkpoint_000002/state.pkl" in names
    assert "results/cut/tune/cut/trial_0/result.json" in names
    assert not any(n.startswith("results/cut/tune/cut/trial_0/checkpoint_") for n in names)
    assert not any(n.startswith("results/done/tune") for n in names)
    assert "results/done/mlartifacts/run1/artifacts/config.yaml" in names
    assert "results/done/optuna.db" in names and "results/cut/optuna.db" in names
    assert not any("/artifacts/checkpoint" in n for n in names)
    # Tune resumes from its newest states; the older ones and TensorBoard's copy of the results stay behind
    tune_names = {n.rsplit("/", 1)[-1] for n in names if n.startswith("results/cut/tune/cut/")}
    assert {
        "experiment_state-2026-12-02_10-00-00.json",
        "basic-variant-state-2026-12-02_10-00-00.json",
    } <= tune_names
    assert not any(n.endswith("2026-12-01_10-00-00.json") or ".tfevents." in n for n in tune_names)
    with tarfile.open(out) as tar:
        manifest = json.loads(tar.extractfile("results/carry.json").read())
        tar.extract("results/carried.db", tmp_path / "unpacked", filter="data")
    assert manifest["root"] == str(tmp_path)
    assert manifest["parts"] == {"done": "finished", "cut": "unfinished", "fresh": "not started"}
    # The snapshot is a whole store: both parents and the cut trial.
    with sqlite3.connect(tmp_path / "unpacked" / "results" / "carried.db") as db:
        assert db.execute("select count(*) from runs").fetchone()[0] == 3

    with_final = tmp_path / "with_final.tar.gz"
    carry.pack(path, with_final, tmp_path, final_checkpoints=True)
    assert "results/done/mlartifacts/run1/artifacts/checkpoint/algorithm_state.pkl" in _names(with_final)


def test_unpacked_in_place_resume_skips_the_finished_part_and_continues_the_cut_one(tmp_path, monkeypatch):
    path, uri, (done, cut, fresh) = _three_parts(tmp_path)
    out = tmp_path / "carried.tar.gz"
    carry.pack(path, out, tmp_path)
    shutil.rmtree(tmp_path / "results")  # a new machine: only the archive is left
    stores.forget_open_stores(str(tmp_path))
    with tarfile.open(out) as tar:
        tar.extractall(tmp_path, filter="data")

    ran = []
    monkeypatch.setattr(sweep, "_import_runtime", lambda: SimpleNamespace(start_ray=lambda a: False))
    monkeypatch.setattr(sweep, "_run_one", lambda spec, args, resume: ran.append((spec.name, resume)) or 0)
    assert sweep.main([str(path), "--resume"]) == 0
    # cut resumes through its Tune state (resume=True): its runs stay, its Optuna studies too.
    assert ran == [("cut", True), ("fresh", False)]
    assert len(tracking.sweep_runs_in_store(uri, cut.experiment, cut.name)[1]) == 2
    assert (tmp_path / "results" / "cut" / "optuna.db").read_bytes() == b"studies"


def test_bad_input_exits_2_naming_it_and_writes_nothing(tmp_path, capsys):
    path, uri, _ = _three_parts(tmp_path)
    out = tmp_path / "out.tar.gz"
    assert carry.main([str(path), str(tmp_path / "out.zip"), "--root", str(tmp_path)]) == 2
    assert "out.zip" in capsys.readouterr().err
    assert carry.main([str(path), str(out), "--root", str(tmp_path / "nowhere")]) == 2
    assert "--root" in capsys.readouterr().err
    assert carry.main([str(tmp_path / "missing.yaml"), str(out), "--root", str(tmp_path)]) == 2
    assert "missing.yaml" in capsys.readouterr().err
    inner = tmp_path / "inner"
    inner.mkdir()
    assert carry.main([str(path), str(out), "--root", str(inner)]) == 2
    assert "is outside --root" in capsys.readouterr().err
    (tmp_path / "results" / "carried.db").unlink()
    stores.forget_open_stores(str(tmp_path))
    assert carry.main([str(path), str(out), "--root", str(tmp_path)]) == 2
    assert f"tracking.uri {uri!r}" in capsys.readouterr().err
    assert not out.exists()


def test_the_spec_is_read_where_the_sweep_ran(tmp_path, monkeypatch, capsys):
    """SPEC relative to --root: a checkout at a later commit packs an older worktree's results with that
    worktree's copy of the file."""
    path, _, _ = _three_parts(tmp_path)
    elsewhere = tmp_path / "checkout"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    out = tmp_path / "packed.tar.gz"
    assert carry.main([path.name, str(out), "--root", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "cut: unfinished, with its Tune folder" in printed and f"packed {out}" in printed
    assert "results/cut/tune/cut/trial_1/checkpoint_000002/state.pkl" in _names(out)


def test_it_says_what_the_archive_holds_and_report_only_leaves_every_tune_folder_out(tmp_path, capsys):
    """An experiment in flight carries its unfinished trials' checkpoints (for --resume only), and says so;
    --report-only packs what a report reads: the store and the artifacts, no Tune folder at all."""
    path, _, _ = _three_parts(tmp_path)
    out = tmp_path / "in_flight.tar.gz"
    assert carry.main([str(path), str(out), "--root", str(tmp_path)]) == 0
    held = capsys.readouterr().out.strip().splitlines()[-1]
    assert held.startswith("holds (unpacked): the MLflow store ")
    assert "checkpoints of unfinished trials (for --resume only) 0.0 MB" in held
    assert "an experiment in flight: commit such an archive only at a session's end" in held
    sizes = carry.contents(out)
    assert sizes["checkpoints of unfinished trials (for --resume only)"] == len(b"weights")
    assert sizes["run artifacts"] == 2 * len("trial: {}\n")  # the final checkpoints are not there

    report = tmp_path / "report.tar.gz"
    assert carry.main([str(path), str(report), "--root", str(tmp_path), "--report-only"]) == 0
    held = capsys.readouterr().out.strip().splitlines()[-1]
    assert "checkpoints" not in held and "in flight" not in held
    names = _names(report)
    assert not any("/tune" in n for n in names)
    assert "results/carried.db" in names and "results/cut/mlartifacts/run1/artifacts/config.yaml" in names
    with tarfile.open(report) as tar:
        assert json.loads(tar.extractfile("results/carry.json").read())["report_only"] is True
    with pytest.raises(SystemExit):  # the two ask for opposite things
        carry.parse_args([str(path), str(report), "--report-only", "--final-checkpoints"])


def test_packed_again_where_an_earlier_archive_was_unpacked_it_holds_one_manifest_the_new_one(tmp_path):
    """A store in its part's own folder (the default uri) carried, unpacked, resumed and packed again: the
    unpacked manifest stays behind (two would read as one broken record in run_at_commit.sh)."""
    base = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    base["tracking"] = {"storage": str(tmp_path / "results")}
    path = tmp_path / "one.yaml"
    path.write_text(yaml.safe_dump(base, sort_keys=False))
    (spec,) = load_specs(path)
    _, parent, _ = tracking.open_sweep_run(spec.tracking.uri, spec.experiment, spec.name, resume=False)
    folder = tmp_path / "results" / spec.name
    (folder / carry.MANIFEST).write_text('{"root": "elsewhere"}')  # an earlier archive's
    out = tmp_path / "again.tar.gz"
    carry.pack(path, out, tmp_path)
    with tarfile.open(out) as tar:
        manifests = [m for m in tar.getmembers() if m.name.endswith(carry.MANIFEST)]
        assert [m.name for m in manifests] == [f"results/{spec.name}/{carry.MANIFEST}"]
        assert json.loads(tar.extractfile(manifests[0]).read())["root"] == str(tmp_path)


def test_an_xz_archive_holds_what_a_gzip_one_holds_and_names_the_suffixes_it_takes(tmp_path, capsys):
    """OUT's name picks the compression: `.tar.xz` packs the same members as `.tar.gz`, in xz (what the
    replay arrays of a long experiment's checkpoints shrink most by); another suffix is refused naming
    both."""
    import lzma

    path, _, _ = _three_parts(tmp_path)
    gz, xz = tmp_path / "in_flight.tar.gz", tmp_path / "in_flight.tar.xz"
    assert carry.main([str(path), str(gz), "--root", str(tmp_path)]) == 0
    assert carry.main([str(path), str(xz), "--root", str(tmp_path)]) == 0
    assert _names(xz) == _names(gz)
    with lzma.open(xz) as raw:  # xz indeed, not gzip under another name
        raw.read(1)
    assert carry.contents(xz) == carry.contents(gz)
    capsys.readouterr()
    assert carry.main([str(path), str(tmp_path / "out.tar.bz2"), "--root", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "out.tar.bz2" in err and ".tar.gz" in err and ".tar.xz" in err
