"""Pack a sweep file's results into one archive that another machine (or session) resumes from.

    python -m copilot_ray.carry SPEC.yaml OUT.tar.gz|OUT.tar.xz [--root DIR] [--final-checkpoints | --report-only]

A comparison runs for longer than one machine may live. The archive holds what ``--resume`` needs:

* the MLflow store: the SQLite file (a consistent snapshot, taken with SQLite's backup API, so even a
  store being written packs whole) and every part's folder (its artifacts, ``spec.yaml``, ``optuna.db``),
  without the final checkpoints logged as run artifacts unless ``--final-checkpoints``;
* the Tune folder (Tune's state, trial folders, the checkpoints of trials not done) of every part the
  store does not record finished: ``--resume`` then continues those trials from their checkpoints instead of starting
  the part over (a stage-2 part of five 200k-step seeds is longer than a session); finished parts go
  without theirs (``--resume`` skips them by the store). Of an unfinished trial's checkpoints only the one
  Tune restores from (the latest its newest experiment state registered) goes with its files; the
  others go as empty folders, so that every folder Tune's state names still exists when Tune deletes
  it by path as the trial goes on. Left out of it: TensorBoard's event files (a copy of the results that
  nothing here reads; Tune starts new ones on resume) and Tune's experiment and searcher states that a
  newer one of the same kind supersedes (Tune resumes from the newest name), which a sweep resumed
  session after session otherwise carries once per session;
* the sweep's log, ``<storage>/<file stem>.log``, when there is one;
* with ``--report-only``, no Tune folder at all: the store and the small artifacts, what a report reads
  (``analysis.report``, ``progress``) and what a results page commits. ``--resume`` from it skips the
  finished parts and starts the unfinished ones over (their unfinished runs discarded first).
* ``<storage>/carry.json``: the folder and the commit it was packed from, which
  ``scripts/run_at_commit.sh --carry`` checks: a store continues only at the commit that began it, and
  at the same path (Tune's state and every trial's config name absolute paths).

It prints what the archive holds (the store, the checkpoints of unfinished trials, the rest). An experiment
in flight carries its unfinished trials' latest checkpoints (their replay buffers with them: megabytes a
seed), which only ``--resume`` needs: commit such an archive at most once, at a session's end, and the
finished store (which has none) once; a results page's store is best packed ``--report-only``. OUT's
name picks the compression: ``.tar.gz`` (gzip) or ``.tar.xz`` (xz), which packs a checkpoint's replay
arrays about 40 % smaller (a 200k-step CO-PILOT checkpoint: 10.1 MB gzip, 6.2 MB xz) at about 3 MB/s,
for the archives of long experiments in flight; both are read by ``tar -xf`` and ``tarfile``.

Stop the sweep first (SIGTERM: Tune saves its state). ``--root`` (default: the current folder) is the
folder the sweep was started from, e.g. the worktree of ``scripts/run_at_commit.sh``: SPEC is read there
(the copy that ran) and paths in the archive are relative to it, so a checkout at a later commit packs an
older worktree's results: ``python -m copilot_ray.carry sweeps/fair_maze.yaml out.tar.gz --root
../main-at-<sha>``. Bad input exits 2 and packs
nothing. No Ray is started; MLflow is imported to read the store, Ray's pickle to read Tune's state.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sqlite3
import sys
import tarfile
import tempfile
from dataclasses import dataclass
from pathlib import Path

from copilot_ray import tracking
from copilot_ray.commands import python_module
from copilot_ray.store import missing_sqlite_file
from copilot_ray.sweep import sweep_root
from copilot_ray.sweep_spec import SpecError, load_specs

MANIFEST = "carry.json"
FINAL_CHECKPOINT = ("artifacts", "checkpoint")  # a run's final checkpoint, as the sweep logs it


class CarryError(RuntimeError):
    """The results cannot be packed as asked (no store, a store outside the folder, ...)."""


@dataclass(frozen=True)
class PartState:
    name: str
    finished: bool
    has_tune: bool

    @property
    def label(self) -> str:
        return "finished" if self.finished else "unfinished" if self.has_tune else "not started"

    def line(self) -> str:
        if self.finished:
            return f"{self.name}: finished in the store (its Tune folder left out; --resume skips it)"
        if self.has_tune:
            return f"{self.name}: unfinished, with its Tune folder (--resume continues from its checkpoints)"
        return f"{self.name}: not started"


def _store_file(specs, root: Path) -> Path:
    uris = {spec.tracking.uri for spec in specs}
    if len(uris) != 1:
        raise CarryError(
            f"the parts write to {len(uris)} stores ({', '.join(sorted(uris))}); carry packs one"
        )
    uri = uris.pop()
    if not uri.startswith("sqlite:///"):
        raise CarryError(
            f"tracking.uri {uri!r} is not a SQLite file; only a file store travels in an archive"
        )
    if (missing := missing_sqlite_file(uri)) is not None:
        raise CarryError(f"tracking.uri {uri!r}: {missing} does not exist (nothing has run from {root}?)")
    path = Path(uri[len("sqlite:///") :]).resolve()
    if not path.is_relative_to(root):
        raise CarryError(f"tracking.uri {uri!r}: {path} is outside --root {root}")
    return path


def part_states(specs) -> list[PartState]:
    uri = specs[0].tracking.uri
    states = []
    for spec in specs:
        finished, _ = tracking.sweep_runs_in_store(uri, spec.experiment, spec.name)
        states.append(PartState(spec.name, finished is not None, (sweep_root(spec) / "tune").is_dir()))
    return states


def _snapshot(db: Path, into: Path) -> Path:
    """A consistent copy of a SQLite file, even while a sweep writes to it."""
    copy = into / db.name
    source, target = sqlite3.connect(f"file:{db}?mode=ro", uri=True), sqlite3.connect(copy)
    try:
        source.backup(target)
    finally:
        source.close()
        target.close()
    return copy


def _trial_finished(trial_folder: Path) -> bool:
    """Whether a Tune trial folder's last result says done (its result.json: one JSON record a line)."""
    results = trial_folder / "result.json"
    try:
        lines = results.read_text().strip().splitlines()
        return bool(lines) and bool(json.loads(lines[-1]).get("done"))
    except (OSError, ValueError):
        return False


def _experiment_folders(tune_folder: Path) -> list[Path]:
    """The Tune experiments under a part's Tune folder (one per env of the part)."""
    return sorted(p for p in tune_folder.iterdir() if p.is_dir()) if tune_folder.is_dir() else []


def _checkpoints_tune_restores(tune_folder: Path) -> dict[Path, Path]:
    """Trial folder -> the checkpoint a resume restores it from, for every trial of every experiment
    under ``tune_folder`` whose newest experiment state (the file Tune itself picks) registered one.
    Trials missing here (no state yet, or one this Ray cannot read) keep all their checkpoints."""
    restores: dict[Path, Path] = {}
    for experiment in _experiment_folders(tune_folder):
        states = sorted(experiment.glob("experiment_state-*.json"))  # Tune resumes from the newest name
        if not states:
            continue
        try:
            trials = json.loads(states[-1].read_text())["trial_data"]
        except (OSError, ValueError, KeyError) as err:
            print(f"note: {states[-1]} unreadable ({err}): its trials keep every checkpoint", file=sys.stderr)
            continue
        for _, run_metadata in trials:
            latest = _latest_checkpoint(run_metadata)
            if latest is not None:
                restores[latest.parent] = latest
    return restores


# Tune's state files, one written per run of the experiment; Tune and its searchers restore from the
# newest name of each kind (`max` of the names matching the pattern).
TUNE_STATE_PATTERNS = (
    "experiment_state-*.json",
    "basic-variant-state-*.json",
    "search_gen_state-*.json",
    "searcher-state-*.pkl",
)
TENSORBOARD_EVENTS = "events.out.tfevents."


def _superseded_states(tune_folder: Path) -> set[Path]:
    """Tune's state files under `tune_folder` that a newer one of the same kind in the same experiment
    folder supersedes."""
    superseded: set[Path] = set()
    for experiment in _experiment_folders(tune_folder):
        for pattern in TUNE_STATE_PATTERNS:
            superseded.update(p.resolve() for p in sorted(experiment.glob(pattern))[:-1])
    return superseded


def _latest_checkpoint(run_metadata: str) -> Path | None:
    """The latest checkpoint a trial's run metadata registered (Tune pickles its checkpoint manager into
    it; the archive is the user's own results, which Tune unpickles on every resume as well)."""
    from ray import cloudpickle

    try:
        manager = json.loads(run_metadata)["checkpoint_manager"]
        result = cloudpickle.loads(bytes.fromhex(manager["value"])).latest_checkpoint_result
    except Exception:  # noqa: BLE001 - any other Ray's format: keep the trial's checkpoints whole
        return None
    return None if result is None else Path(result.checkpoint.path).resolve()


def _checkpoint_folder(path: Path) -> Path | None:
    """The ``checkpoint_*`` folder of a trial that ``path`` lies in, if any."""
    for folder in path.parents:
        if folder.name.startswith("checkpoint_"):
            return folder
    return None


# An archive's name picks its compression; xz packs the checkpoints' float arrays about 40 % smaller.
ARCHIVE_MODES = {".tar.gz": "w:gz", ".tgz": "w:gz", ".tar.xz": "w:xz"}


def _open_for_writing(out: Path) -> tarfile.TarFile:
    """`out` opened for writing with the compression its name says (gzip for any other name)."""
    mode = next((m for suffix, m in ARCHIVE_MODES.items() if out.name.endswith(suffix)), "w:gz")
    return tarfile.open(out, mode, preset=6) if mode == "w:xz" else tarfile.open(out, mode)


def pack(
    spec_path: str | Path, out: Path, root: Path, final_checkpoints: bool = False, report_only: bool = False
) -> list[PartState]:
    """Writes the archive (see the module's doc) and returns each part's state as packed."""
    specs = load_specs(spec_path)  # relative storage and store paths resolve against the current folder
    db = _store_file(specs, root)
    states = part_states(specs)
    # The Tune folders of finished parts stay behind (--resume skips those parts by the store).
    finished_tune = {
        sweep_root(s) / "tune" for s, st in zip(specs, states, strict=True) if st.finished or report_only
    }
    restores: dict[Path, Path] = {}
    superseded: set[Path] = set()
    for spec, state in zip(specs, states, strict=True):
        if not state.finished and not report_only:
            tune_folder = (root / sweep_root(spec) / "tune").resolve()
            restores |= _checkpoints_tune_restores(tune_folder)
            superseded |= _superseded_states(tune_folder)

    def keep(info: tarfile.TarInfo) -> tarfile.TarInfo | None:
        path = root / info.name
        if path.name.startswith(db.name):  # the store (and its -wal, -shm): its snapshot goes in instead
            return None
        if path == db.parent / MANIFEST:  # an earlier archive's, unpacked here: this one writes its own
            return None
        if path in finished_tune:
            return None
        if not final_checkpoints and path.parts[-2:] == FINAL_CHECKPOINT:
            return None
        if path.name.startswith(TENSORBOARD_EVENTS) or (not info.isdir() and path.resolve() in superseded):
            return None
        if info.isdir() and path.name.startswith("checkpoint_") and _trial_finished(path.parent):
            return None  # Tune skips a finished trial on resume and never loads its checkpoints
        checkpoint = _checkpoint_folder(path)
        if checkpoint is not None and not info.isdir():
            trial = checkpoint.parent.resolve()
            if trial in restores and restores[trial] != checkpoint.resolve():
                return None  # a checkpoint Tune will not load: its folder goes, empty (see the module doc)
        return info

    storage = db.parent
    log = storage / f"{Path(spec_path).stem}.log"
    manifest = {
        "root": str(root),
        "commit": tracking.git_commit(root),
        "spec": str(spec_path),
        "parts": {s.name: s.label for s in states},
        "report_only": report_only,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, _open_for_writing(out) as archive:
        archive.add(_snapshot(db, Path(tmp)), arcname=str(db.relative_to(root)))
        for spec in specs:
            folder = sweep_root(spec)
            if folder.is_dir():
                archive.add(folder, arcname=str(folder.relative_to(root)), filter=keep)
        if log.is_file():
            archive.add(log, arcname=str(log.relative_to(root)))
        (Path(tmp) / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
        archive.add(Path(tmp) / MANIFEST, arcname=str((storage / MANIFEST).relative_to(root)))
    return states


# What an archive's members are, in the order `contents` names them.
KINDS = (
    "the MLflow store",
    "checkpoints of unfinished trials (for --resume only)",
    "Tune's state and trial logs",
    "run artifacts",
    "logs and the rest",
)


def contents(archive: Path) -> dict[str, int]:
    """Bytes (unpacked) per kind of member (KINDS) of an archive `pack` wrote."""
    sizes = dict.fromkeys(KINDS, 0)
    with tarfile.open(archive) as tar:
        for member in tar.getmembers():
            if not member.isfile():
                continue
            parts = Path(member.name).parts
            if member.name.endswith(".db") and "tune" not in parts and "mlartifacts" not in parts:
                kind = KINDS[0] if not member.name.endswith("optuna.db") else KINDS[4]
            elif "tune" in parts and any(p.startswith("checkpoint_") for p in parts):
                kind = KINDS[1]
            elif "tune" in parts:
                kind = KINDS[2]
            elif "mlartifacts" in parts:
                kind = KINDS[3]
            else:
                kind = KINDS[4]
            sizes[kind] += member.size
    return sizes


def contents_line(archive: Path) -> str:
    sizes = contents(archive)
    held = ", ".join(f"{kind} {n / 1e6:.1f} MB" for kind, n in sizes.items() if n)
    line = f"holds (unpacked): {held or 'nothing'}"
    if sizes[KINDS[1]]:
        line += (
            "; an experiment in flight: commit such an archive only at a session's end, and the finished "
            "store once (or pack --report-only, without Tune's folders)"
        )
    return line


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog=python_module("copilot_ray.carry"), description=__doc__.split("\n\n")[0])
    p.add_argument(
        "spec", help="the sweep file whose results to pack, relative to --root (the copy that ran)"
    )
    p.add_argument("out", help="the archive to write (.tar.gz, or .tar.xz: smaller, slower to pack)")
    p.add_argument("--root", default=".", help="the folder the sweep was started from (default: here)")
    which = p.add_mutually_exclusive_group()
    which.add_argument(
        "--final-checkpoints", action="store_true", help="keep the final checkpoints logged as run artifacts"
    )
    which.add_argument(
        "--report-only",
        action="store_true",
        help="no Tune folders: the store and small artifacts a report reads (unfinished parts restart on --resume)",
    )
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    root = Path(args.root).expanduser().resolve()
    out = Path(args.out).expanduser().resolve()
    if not root.is_dir():
        print(f"error: --root {args.root!r} is not a folder", file=sys.stderr)
        return 2
    if not out.name.endswith(tuple(ARCHIVE_MODES)):
        print(f"error: out {args.out!r} must name a {' or '.join(ARCHIVE_MODES)} file", file=sys.stderr)
        return 2
    spec = Path(args.spec).expanduser()
    spec = spec if spec.is_absolute() else root / spec  # the file as it ran there, not this checkout's
    try:
        with contextlib.chdir(root):  # the spec's relative storage and store resolve where it was started
            states = pack(spec, out, root, args.final_checkpoints, args.report_only)
    except SpecError as err:
        for line in err.problems:
            print(line, file=sys.stderr)
        return 2
    except CarryError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for state in states:
        print(state.line())
    print(f"packed {out} ({out.stat().st_size / 1e6:.1f} MB) from {root}")
    print(contents_line(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
