"""What a call of the GPU machine would carry from this checkout, and how to leave the stores behind.

    python3 scripts/device_tree.py size [--carry PATH ...] [--if-parked] [--top 15] [--list]
    python3 scripts/device_tree.py park       # docs/' stores, figures and tables into .parked/ (ignored)
    python3 scripts/device_tree.py unpark     # and back
    python3 scripts/device_tree.py status

`size` counts what travels, as the device tool does: the tracked files present in the working tree, the
untracked files git does not ignore, a `shared/` folder, and every path named with `--carry` (default:
device_wheels, the wheels `scripts/gather_device_wheels.sh` makes; where they are not gathered here,
their sizes from its manifest, scripts/device_wheels.json). It prints the largest files, the total per
top-level folder and the total against the call's 64 MiB, and exits 1 above it (2 on bad input).
`--if-parked` counts as though `park` had run (what the test suite checks, without moving anything).

`park` moves every file under docs/ that a run on that machine never reads (store archives, figures,
compressed tables: PARKED_SUFFIXES, and any file of PARKED_BYTES or more) into .parked/ at the same
relative path, so that it does not travel (an ignored folder, and a file absent from the working tree,
are not copied). Tracked files are marked skip-worktree while parked, so `git status` stays clean and
`git commit -a` cannot record them deleted; `unpark` moves them back and clears the mark (a file that
is back in its place already, identical, is dropped from .parked/; a different one is left in both
places and named, exit 1). .parked/manifest.json lists what is parked. Unpark before switching
branches or pulling. Standard library and git only: it runs on any Python, that machine's too.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 64 * 2**20  # the device tool's limit on what travels
WHEELS = "device_wheels"
WHEELS_MANIFEST = Path("scripts") / "device_wheels.json"
PARKED = ".parked"
PARKED_MANIFEST = "manifest.json"
PARKED_FOLDERS = ("docs/",)
PARKED_SUFFIXES = (
    ".tar.gz",
    ".tgz",
    ".png",
    ".jpg",
    ".jpeg",
    ".gif",
    ".pdf",
    ".csv.gz",
    ".jsonl",
    ".db",
    ".html",
)
PARKED_BYTES = 256 * 2**10


@dataclass(frozen=True)
class Entry:
    path: str  # relative to the root, with / separators
    size: int
    source: str  # "tracked", "untracked", "shared", "carry" or "manifest"


def _git(root: Path, *args: str, stdin: bytes | None = None) -> bytes:
    return subprocess.run(
        ["git", "-C", str(root), *args], input=stdin, check=True, capture_output=True
    ).stdout


def _git_paths(root: Path, *args: str) -> list[str]:
    return [p for p in _git(root, *args, "-z").decode().split("\0") if p]


def parkable(path: str, size: int) -> bool:
    """A file under docs/ that no run on the GPU machine reads: a result archive, a figure, a table."""
    return path.startswith(PARKED_FOLDERS) and (path.endswith(PARKED_SUFFIXES) or size >= PARKED_BYTES)


def _size(path: Path) -> int | None:
    """A plain file's or a link's own size (a link travels as a link); None for folders and the absent."""
    try:
        info = path.lstat()
    except OSError:
        return None
    if path.is_symlink() or path.is_file():
        return info.st_size
    return None


def _walk(root: Path, rel: str, source: str) -> list[Entry]:
    top = root / rel
    if _size(top) is not None:
        return [Entry(rel, _size(top), source)]
    found = []
    for folder, dirs, files in os.walk(top):
        dirs.sort()
        for name in sorted(files):
            path = Path(folder) / name
            size = _size(path)
            if size is not None:
                found.append(Entry(path.relative_to(root).as_posix(), size, source))
    return found


def wheels_manifest(root: Path) -> dict | None:
    try:
        return json.loads((root / WHEELS_MANIFEST).read_text())
    except (OSError, ValueError):
        return None


def travelling(root: Path, carry: list[str], if_parked: bool = False) -> tuple[list[Entry], list[str]]:
    """(every file that would travel, notes). Tracked files absent from the working tree do not."""
    entries: dict[str, Entry] = {}
    notes = []
    tracked = _git_paths(root, "ls-files", "--cached")
    untracked = _git_paths(root, "ls-files", "--others", "--exclude-standard")
    for paths, source in ((tracked, "tracked"), (untracked, "untracked")):
        for rel in paths:
            size = _size(root / rel)  # a submodule's folder travels without its files: None
            if size is not None:
                entries[rel] = Entry(rel, size, source)
    if (root / "shared").is_dir():
        for e in _walk(root, "shared", "shared"):
            entries.setdefault(e.path, e)
    for rel in carry:
        rel = Path(rel).as_posix().rstrip("/")
        if (root / rel).exists() or (root / rel).is_symlink():
            for e in _walk(root, rel, "carry"):
                entries[e.path] = e
            if rel == WHEELS and (manifest := wheels_manifest(root)) is not None:
                have = {e.path.rsplit("/", 1)[-1] for e in entries.values() if e.path.startswith(rel + "/")}
                want = {w["file"] for w in manifest["wheels"]}
                if have != want:
                    notes.append(
                        f"note: {rel}/ differs from {WHEELS_MANIFEST} (missing: {sorted(want - have) or 'none'}; "
                        f"extra: {sorted(have - want) or 'none'}): run scripts/gather_device_wheels.sh again"
                    )
        elif rel == WHEELS and (manifest := wheels_manifest(root)) is not None:
            for w in manifest["wheels"]:
                path = f"{rel}/{w['file']}"
                entries[path] = Entry(path, int(w["bytes"]), "manifest")
            notes.append(f"note: {rel}/ is not gathered here: its wheels counted from {WHEELS_MANIFEST}")
        else:
            notes.append(f"note: --carry {rel}: not here (the call would remove it there)")
    found = sorted(entries.values(), key=lambda e: e.path)
    if if_parked:
        found = [e for e in found if e.source not in ("tracked", "untracked") or not parkable(e.path, e.size)]
    return found, notes


def _mib(n: int) -> str:
    return f"{n / 2**20:.1f} MiB"


def size_report(entries: list[Entry], top: int, list_all: bool) -> list[str]:
    lines = []
    shown = entries if list_all else sorted(entries, key=lambda e: -e.size)[:top]
    lines.append("every file that travels:" if list_all else f"the {len(shown)} largest files:")
    lines += [f"  {_mib(e.size):>10}  {e.path}  ({e.source})" for e in shown]
    folders: dict[str, list[int]] = {}
    for e in entries:
        head = e.path.split("/", 1)[0] if "/" in e.path else "."
        folders.setdefault(head, []).append(e.size)
    lines.append("per top-level folder:")
    for head, sizes in sorted(folders.items(), key=lambda kv: -sum(kv[1])):
        lines.append(
            f"  {_mib(sum(sizes)):>10}  {head}/ ({len(sizes)} files)"
            if head != "."
            else f"  {_mib(sum(sizes)):>10}  files at the top ({len(sizes)})"
        )
    return lines


def cmd_size(root: Path, args) -> int:
    entries, notes = travelling(root, args.carry, args.if_parked)
    total = sum(e.size for e in entries)
    for line in size_report(entries, args.top, args.list):
        print(line)
    for line in notes:
        print(line)
    state = (
        "as though parked" if args.if_parked else ("stores parked" if parked_entries(root) else "as it is")
    )
    verdict = "fits" if total <= LIMIT else f"OVER by {_mib(total - LIMIT)}"
    print(
        f"travels: {_mib(total)} in {len(entries)} files ({state}; carried: {', '.join(args.carry) or 'nothing'}) "
        f"of the call's 64 MiB: {verdict}"
    )
    if total > LIMIT and not args.if_parked:
        parkable_bytes = sum(
            e.size for e in entries if e.source in ("tracked", "untracked") and parkable(e.path, e.size)
        )
        if parkable_bytes:
            print(f"  `python3 scripts/device_tree.py park` leaves {_mib(parkable_bytes)} of docs/ behind")
    return 0 if total <= LIMIT else 1


def parked_entries(root: Path) -> list[dict]:
    try:
        return json.loads((root / PARKED / PARKED_MANIFEST).read_text())["files"]
    except (OSError, ValueError, KeyError):
        return []


def _write_parked(root: Path, files: list[dict]) -> None:
    folder = root / PARKED
    if not files:
        (folder / PARKED_MANIFEST).unlink(missing_ok=True)
        return
    folder.mkdir(exist_ok=True)
    (folder / PARKED_MANIFEST).write_text(
        json.dumps(
            {
                "what": "files `scripts/device_tree.py park` moved here; `unpark` moves them back",
                "files": files,
            },
            indent=1,
        )
        + "\n"
    )


def _skip_worktree(root: Path, paths: list[str], on: bool) -> None:
    if paths:
        flag = "--skip-worktree" if on else "--no-skip-worktree"
        _git(root, "update-index", flag, "-z", "--stdin", stdin=("\0".join(paths) + "\0").encode())


def _prune_empty(folder: Path, stop: Path) -> None:
    while folder != stop and folder.is_dir() and not any(folder.iterdir()):
        folder.rmdir()
        folder = folder.parent


def cmd_park(root: Path, args) -> int:
    tracked = set(_git_paths(root, "ls-files", "--cached"))
    candidates = tracked | set(_git_paths(root, "ls-files", "--others", "--exclude-standard"))
    files = parked_entries(root)
    already = {f["path"] for f in files}
    moved, clashes = [], []
    for rel in sorted(candidates):
        size = _size(root / rel)
        if size is None or not parkable(rel, size) or (root / rel).is_symlink():
            continue
        target = root / PARKED / rel
        if target.exists() and not filecmp.cmp(root / rel, target, shallow=False):
            clashes.append(rel)
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(root / rel, target)
        moved.append({"path": rel, "bytes": size, "tracked": rel in tracked})
        _prune_empty((root / rel).parent, root)
    files = [f for f in files if f["path"] not in {m["path"] for m in moved}] + moved
    _write_parked(root, files)
    _skip_worktree(root, [m["path"] for m in moved if m["tracked"]], True)
    print(
        f"parked {len(moved)} files ({_mib(sum(m['bytes'] for m in moved))}) in {PARKED}/"
        + (f"; {len(already)} were parked before" if already else "")
        + f"; {len(files)} parked in all: `python3 scripts/device_tree.py unpark` puts them back"
    )
    for rel in clashes:
        print(f"error: {PARKED}/{rel} exists and differs from {rel}: left both as they are", file=sys.stderr)
    return 1 if clashes else 0


def cmd_unpark(root: Path, args) -> int:
    files = parked_entries(root)
    left, back = [], []
    for f in files:
        rel, parked = f["path"], root / PARKED / f["path"]
        place = root / rel
        if not parked.exists():
            if not place.exists():
                print(f"error: {rel}: neither in its place nor in {PARKED}/", file=sys.stderr)
                left.append(f)
            else:
                back.append(f)
            continue
        if place.exists():
            if filecmp.cmp(place, parked, shallow=False):
                parked.unlink()
                back.append(f)
            else:
                print(
                    f"error: {rel} is back in its place and differs from {PARKED}/{rel}: both kept",
                    file=sys.stderr,
                )
                left.append(f)
            continue
        place.parent.mkdir(parents=True, exist_ok=True)
        os.replace(parked, place)
        back.append(f)
    for f in back:
        _prune_empty((root / PARKED / f["path"]).parent, root / PARKED)
    _skip_worktree(root, [f["path"] for f in back if f.get("tracked")], False)
    _write_parked(root, left)
    if not left and (root / PARKED).is_dir() and not any((root / PARKED).iterdir()):
        shutil.rmtree(root / PARKED)
    print(
        f"unparked {len(back)} files ({_mib(sum(f['bytes'] for f in back))})"
        + (f"; {len(left)} left in {PARKED}/" if left else "")
    )
    return 1 if left else 0


def cmd_status(root: Path, args) -> int:
    files = parked_entries(root)
    if files:
        print(
            f"{len(files)} files parked in {PARKED}/ ({_mib(sum(f['bytes'] for f in files))}): unpark to put them back"
        )
    else:
        print("nothing parked")
    entries, _ = travelling(root, [])
    waiting = [e for e in entries if parkable(e.path, e.size)]
    if waiting:
        print(f"{len(waiting)} files under docs/ would be parked now ({_mib(sum(e.size for e in waiting))})")
    return 0


def parse_args(argv=None):
    p = argparse.ArgumentParser(prog="python3 scripts/device_tree.py", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    size = sub.add_parser("size", help="what travels, and whether it fits 64 MiB (exit 1 if not)")
    size.add_argument(
        "--carry", nargs="*", default=[WHEELS], help=f"the ignored paths the call carries (default: {WHEELS})"
    )
    size.add_argument("--if-parked", action="store_true", help="count as though `park` had run")
    size.add_argument(
        "--top", type=int, default=15, help="how many of the largest files to name (default 15)"
    )
    size.add_argument("--list", action="store_true", help="name every file")
    sub.add_parser("park", help="move docs/' large results into .parked/")
    sub.add_parser("unpark", help="move them back")
    sub.add_parser("status", help="what is parked, and what would be")
    p.add_argument("--root", default=str(ROOT), help="the checkout (default: this script's)")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    root = Path(args.root).resolve()
    try:
        _git(root, "rev-parse", "--git-dir")
    except (subprocess.CalledProcessError, FileNotFoundError):
        print(f"error: --root {args.root!r} is not a git checkout", file=sys.stderr)
        return 2
    return {"size": cmd_size, "park": cmd_park, "unpark": cmd_unpark, "status": cmd_status}[args.command](
        root, args
    )


if __name__ == "__main__":
    raise SystemExit(main())
