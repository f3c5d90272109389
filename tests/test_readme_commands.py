"""Every command the README shows still works: specs load, flags parse and pass their checks, a report
command names an experiment that a shipped spec writes into the store it points at, and a benchmark's
flags are flags of that benchmark. (The commands themselves run elsewhere: the quick start in CI, the
sweeps for hours.) A report drawn from a store the repository ships (`tar xzf docs/.../store.tar.gz -C
DIR`, then the report on DIR's store) does run here, as on a clone: unpacked into a temporary folder, its
tables compared with the shipped report's. Nothing here starts Ray."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


# A code block's line that is a command; an indented list item's prose that names one is not.
COMMAND_START = re.compile(
    r"(?:[A-Z_]+=\S+ )*(?:\.venv/bin/python|python|bash|cd|pip|\.ci/|mlflow|tar|git|mkdir)\b"
)


def _block_commands(text: str = README) -> list[str]:
    """Commands in the README's code blocks (4-space indented), continuations joined."""
    lines, out, pending = text.splitlines(), [], ""
    for line in lines:
        if line.startswith("    ") and not line.strip().startswith("#"):
            if not pending and not COMMAND_START.match(line.strip()):
                continue
            text = pending + line.strip()
            if text.endswith("\\"):
                pending = text[:-1] + " "
                continue
            pending = ""
            out.append(text.split("  #")[0].strip())
    return out


def _commands() -> list[str]:
    """Python commands in the README's code blocks and inline code."""
    out = _block_commands() + re.findall(r"`((?:PYTHONPATH=\. )?\.venv/bin/python [^`]+)`", README)
    return [c for c in out if "python" in c]


def _script_commands(script: str) -> list[str]:
    """Commands that run `script`, from code blocks and inline code (which may wrap over lines)."""
    blocks = [line.strip().split("  #")[0] for line in README.splitlines() if line.startswith("    ")]
    found = re.findall(r"`([^`#]*?" + re.escape(script) + r"[^`#]*)`", README)
    inline = [" ".join(c.split()) for c in found if c.count("\n") <= 2]  # not a code block's stretch
    return [c[c.index("bash ") :] for c in blocks + inline if script in c and "bash " in c]


def _args(command: str, marker: str) -> list[str]:
    return shlex.split(command.split(marker, 1)[1].replace("$PWD", str(ROOT)))


COMMANDS = _commands()
SWEEPS = [c for c in COMMANDS if "-m copilot_ray.sweep " in c]
REPORTS = [c for c in COMMANDS if "-m analysis.report " in c]
TRAINS = [c for c in COMMANDS if "-m copilot_ray.train" in c]
BENCHMARKS = [c for c in COMMANDS if "benchmarks/" in c and "<" not in c]
CARRIES = [c for c in COMMANDS if "-m copilot_ray.carry " in c]
PROGRESSES = [c for c in COMMANDS if "-m copilot_ray.progress " in c]
PINNED_RUNS = _script_commands("scripts/run_at_commit.sh")
# `tar xzf ARCHIVE -C DIR`: a store the repository ships, unpacked where a report reads it (folder ->
# its archives: two may unpack into one folder, a comparison's store and a part's beside it)
UNPACKS: dict[str, list[str]] = {}
for _c in _block_commands():
    if _m := re.fullmatch(r"tar xzf (\S+\.tar\.gz) -C (\S+)", _c):
        UNPACKS.setdefault(_m.group(2), []).append(_m.group(1))


def _unpacked(uri: str | None) -> tuple[str, str] | None:
    """(the unpack folder, the store's path inside it) when `uri` reads a store a README `tar xzf` puts
    there; None otherwise."""
    for folder in UNPACKS:
        prefix = f"sqlite:///$PWD/{folder}/"
        if uri is not None and uri.startswith(prefix):
            return folder, uri[len(prefix) :]
    return None


def _raw_args(command: str, marker: str) -> list[str]:
    return shlex.split(command.split(marker, 1)[1])


def _stores(args: list[str]) -> list[int]:
    """The positions in `args` of every store URI (--tracking-uri, --also-from)."""
    return [i + 1 for i, a in enumerate(args) if a in ("--tracking-uri", "--also-from")]


SHIPPED_REPORTS = [
    c
    for c in REPORTS
    if any(_unpacked(a) for a in _raw_args(c, "-m analysis.report ") if a.startswith("sqlite:"))
]


def test_the_readme_shows_each_kind_of_command():
    assert SWEEPS and REPORTS and TRAINS and BENCHMARKS and CARRIES and PROGRESSES and PINNED_RUNS
    assert UNPACKS and SHIPPED_REPORTS


@pytest.mark.parametrize("folder", sorted(UNPACKS))
def test_unpack_commands_name_a_shipped_archive_into_an_ignored_folder(folder):
    """Each archive is in the repository; the folder is one git ignores (a store is not committed
    twice), and a `mkdir -p` of the README makes it first (tar -C needs it)."""
    import subprocess

    for archive in UNPACKS[folder]:
        assert (ROOT / archive).is_file(), archive
    ignored = subprocess.run(["git", "check-ignore", "-q", folder], cwd=ROOT)
    assert ignored.returncode == 0, f"{folder} is not ignored by git"
    assert any(c.startswith("mkdir -p") and folder in c.split() for c in _block_commands())


@pytest.mark.parametrize("command", SHIPPED_REPORTS)
def test_a_report_of_a_shipped_store_works_on_a_clone(command, tmp_path):
    """As a clone would: every store the command reads is in an archive the README unpacks into its
    folder, and the command says --no-log (the store's runs name another machine's artifact paths, and
    its sweep runs are the record: not the reader's to log into). A command whose --out is a shipped
    report (docs/.../report) is run on the archives unpacked into a temporary folder: exit 0, and that
    report's figures and readings come out again (the shipped report is what the command makes). One
    that writes elsewhere is checked this far only."""
    import tarfile

    import pandas as pd

    from analysis.report import main, parse_args

    args = _raw_args(command, "-m analysis.report ")
    assert "--no-log" in args
    parse_args([a.replace("$PWD", str(ROOT)) for a in args])
    for i in _stores(args):
        folder, store = _unpacked(args[i])
        names = set()
        for archive in UNPACKS[folder]:
            with tarfile.open(ROOT / archive) as packed:
                names |= set(packed.getnames())
        assert store in names, f"no archive unpacked into {folder} holds {store}"
    shipped = ROOT / args[args.index("--out") + 1]
    if not (shipped / "report.md").is_file():
        return
    for folder in {_unpacked(args[i])[0] for i in _stores(args)}:
        for archive in UNPACKS[folder]:
            with tarfile.open(ROOT / archive) as packed:
                packed.extractall(tmp_path / folder, filter="data")
    for i in _stores(args):
        folder, store = _unpacked(args[i])
        args[i] = f"sqlite:///{tmp_path / folder / store}"
    args[args.index("--out") + 1] = str(tmp_path / "report")
    assert main(args) == 0
    for name, key, columns in (
        ("summary.csv", "configuration", ["n_seeds", "success_final", "success_final_low", "success_auc"]),
        ("improvement.csv", "other", ["p_final", "p_final_reading", "p_auc", "p_auc_reading"]),
    ):
        if not (shipped / name).is_file():
            assert not (tmp_path / "report" / name).is_file()
            continue
        mine = pd.read_csv(tmp_path / "report" / name).set_index(key)
        theirs = pd.read_csv(shipped / name).set_index(key)
        pd.testing.assert_frame_equal(mine[columns], theirs[columns], check_exact=False, rtol=1e-9)
    counts = ["collision_checks", "resets", "map_queries"]
    mine = pd.read_csv(tmp_path / "report" / "summary.csv").set_index("configuration")
    theirs = pd.read_csv(shipped / "summary.csv").set_index("configuration")
    pd.testing.assert_frame_equal(mine[counts], theirs[counts], check_exact=False, rtol=1e-9)


@pytest.mark.parametrize("command", CARRIES)
def test_carry_commands_name_a_valid_spec_and_an_archive(command):
    from copilot_ray.carry import parse_args
    from copilot_ray.sweep_spec import load_specs

    args = parse_args(_args(command, "-m copilot_ray.carry "))
    assert load_specs(ROOT / args.spec) and args.out.endswith(".tar.gz")


@pytest.mark.parametrize("command", PINNED_RUNS)
def test_pinned_run_commands_use_the_scripts_options_a_shipped_spec_and_sweep_flags(command):
    """`bash scripts/run_at_commit.sh [--commit REV] [--spec-from REV2] [--carry F] SPEC [sweep flags]`:
    its options are the script's (read off its usage line), SPEC a shipped spec, the rest sweep flags."""
    from copilot_ray.sweep import parse_args
    from copilot_ray.sweep_spec import load_specs

    script = (ROOT / "scripts" / "run_at_commit.sh").read_text()
    usage = next(line for line in script.splitlines() if "usage: bash scripts/run_at_commit.sh" in line)
    options = set(re.findall(r"\[(--[a-z-]+) ", usage))
    assert {"--commit", "--spec-from", "--carry"} <= options
    words = shlex.split(command.replace("<sha>", "abc1234"))[2:]
    while words and words[0].startswith("--"):
        assert words[0] in options, (words[0], command)
        words = words[2:]
    spec, flags = words[0], words[1:]
    assert load_specs(ROOT / spec)
    parse_args([spec, *flags])


@pytest.mark.parametrize("command", PROGRESSES)
def test_progress_commands_name_a_valid_spec(command):
    from copilot_ray.progress import parse_args
    from copilot_ray.sweep_spec import load_specs

    assert load_specs(ROOT / parse_args(_args(command, "-m copilot_ray.progress ")).spec)


@pytest.mark.parametrize("command", SWEEPS)
def test_sweep_commands_name_a_valid_spec_and_flags(command):
    from copilot_ray.store import tracking_uri_problem
    from copilot_ray.sweep import parse_args
    from copilot_ray.sweep_spec import load_specs

    args = parse_args(_args(command, "-m copilot_ray.sweep "))
    assert load_specs(ROOT / args.spec)
    assert args.tracking_uri is None or tracking_uri_problem(args.tracking_uri) is None


def _shipped_stores() -> dict[tuple[str, str], str]:
    """(experiment, store URI as run from the repository's root) -> the spec file that writes it."""
    import os

    from copilot_ray.sweep_spec import load_specs

    out = {}
    cwd = os.getcwd()
    os.chdir(ROOT)  # relative storage and sqlite paths resolve against where the sweep is started
    try:
        for path in sorted((ROOT / "sweeps").glob("*.yaml")):
            for spec in load_specs(path):
                out[(spec.experiment, spec.tracking.uri)] = path.name
    finally:
        os.chdir(cwd)
    return out


# The report commands of the experiment pages (docs/<experiment>/README.md: the command a rule fixed before
# the run says will read it), their worktree placeholder (`../<checkout folder>-at-<sha>`) filled as
# scripts/run_at_commit.sh names one.
PAGE_REPORTS = [
    re.sub(r"\.\./[^/]*-at-<[^>]+>", "../main-at-0000000", c)
    for page in sorted((ROOT / "docs").glob("*/README.md"))
    for c in _block_commands(page.read_text())
    if "-m analysis.report " in c
]


def test_the_experiment_pages_show_their_report_commands():
    pages = "\n".join(PAGE_REPORTS)
    assert "copilot-depth-k" in pages and "copilot-cotraining" in pages


@pytest.mark.parametrize("command", REPORTS + PAGE_REPORTS)
def test_report_commands_name_an_experiment_a_shipped_spec_writes_there(command):
    from analysis.report import parse_args

    args = _args(command, "-m analysis.report ")
    parsed = parse_args(args)  # every flag exists and takes its value (a bad one exits here)
    experiment = parsed.experiment
    stores = _shipped_stores()
    experiments = {e for e, _ in stores}
    assert experiment in experiments, f"{experiment!r} is no shipped spec's experiment: {sorted(experiments)}"
    also = parsed.also_experiment or experiment  # the --also-from stores' experiment
    pairs = [(experiment, parsed.tracking_uri)] + [(also, uri) for uri in parsed.also_from]
    for name, uri in pairs:
        if uri is None:
            continue
        # a pinned worktree beside this checkout (scripts/run_at_commit.sh: ../<checkout>-at-<sha7>) keeps
        # a spec's store at the same path under it, and so does a shipped archive unpacked into a folder
        # (`tar xzf ... -C FOLDER`, the store packed from that worktree)
        here = re.sub(r"/\.\./[^/]+-at-[0-9a-f]{7}/", "/", uri)
        for folder in UNPACKS:
            here = here.replace(f"{ROOT}/{folder}/", f"{ROOT}/", 1)
        assert (name, here) in stores, f"no shipped spec writes {name!r} into {uri}"


@pytest.mark.parametrize("command", TRAINS)
def test_train_commands_parse_and_pass_their_checks(command):
    from copilot_ray import train
    from copilot_ray.registry import get_algorithm
    from copilot_ray.settings import problems

    argv = _args(command, "-m copilot_ray.train")
    if "--help" in argv:
        with pytest.raises(SystemExit) as done:
            train.parse_args(argv)
        assert done.value.code == 0
        return
    args = train.parse_args(argv)
    assert train.run_problems(args) == []
    assert problems(get_algorithm("copilot").settings, train.setting_values(args)) == []


@pytest.mark.parametrize("command", BENCHMARKS)
def test_benchmark_commands_use_flags_the_benchmark_has(command):
    script = re.search(r"benchmarks/\w+\.py", command).group(0)
    source = (ROOT / script).read_text()
    for flag in re.findall(r"(?<!\S)--[a-z][a-z0-9-]*", command.split(script, 1)[1]):
        assert f'"{flag}"' in source, f"{script} has no {flag}"


def test_the_python_snippets_imports_exist():
    """The "From Python" lines (`from copilot_ray... import ...`, the progress one-liner included) import
    what they name; nothing is built or started."""
    lines = [
        line.strip().split("  #")[0]
        for line in README.splitlines()
        if line.startswith("    from copilot_ray")
    ]
    assert any("show_progress" in line for line in lines), "the README's snippet shows no progress"
    for line in lines:
        statements = [part.strip() for part in line.split(";")]
        exec("\n".join(s for s in statements if s.startswith("from ")), {})  # noqa: S102 - README's own lines
