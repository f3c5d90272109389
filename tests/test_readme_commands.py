"""Every command the README shows still works: specs load, flags parse and pass their checks, a report
command names an experiment that a shipped spec writes into the store it points at, and a benchmark's
flags are flags of that benchmark. (The commands themselves run elsewhere: the quick start in CI, the
sweeps for hours.) Nothing here starts Ray."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


# A code block's line that is a command; an indented list item's prose that names one is not.
COMMAND_START = re.compile(
    r"(?:[A-Z_]+=\S+ )*(?:\.venv/bin/python|python|bash|cd|pip|\.ci/|mlflow|tar|git)\b"
)


def _commands() -> list[str]:
    """Commands in the README's code blocks (4-space indented) and inline code, continuations joined."""
    lines, out, pending = README.splitlines(), [], ""
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
    out += re.findall(r"`((?:PYTHONPATH=\. )?\.venv/bin/python [^`]+)`", README)
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


def test_the_readme_shows_each_kind_of_command():
    assert SWEEPS and REPORTS and TRAINS and BENCHMARKS and CARRIES and PROGRESSES and PINNED_RUNS


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


@pytest.mark.parametrize("command", REPORTS)
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
        # a spec's store at the same path under it
        here = re.sub(r"/\.\./[^/]+-at-[0-9a-f]{7}/", "/", uri)
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
