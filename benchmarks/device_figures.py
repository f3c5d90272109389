"""Every figure the GPU check is for, one line each, from what `scripts/device_check.sh` left in its folder:
measured, or why not (`not reached (cut at N s)`, `skipped: no CUDA device`, `failed: ...`).

    python3 benchmarks/device_figures.py OUT [--write]     # on the machine, as the check's last step
    python3 benchmarks/device_figures.py --record OUT      # here, on the folder fetched from $OUT

It reads OUT/steps.jsonl (each step's cap, exit status and seconds, written by the script),
OUT/figures.jsonl (the update-alone rows and agreement checks of benchmarks/device_throughput.py, the
sweep's trial rates of benchmarks/device_sweep.py), OUT/trials.jsonl (device_throughput's trial
iterations) and OUT/device_check.txt (the printed rows of benchmarks/stacked_update.py and
benchmarks/stacked_trial.py, read by their line formats: a line that stops matching says so). FIGURES
lists the figures, with the targets the issues set; each prints as `figure <key>: <label>: <value>`.

It writes OUT/device_figures.json (every figure, the machine, the commit). `--write`, where a GPU trial
measured a rate: the GPU section of copilot_ray/measured_throughput.json (`env_steps_per_s_gpu`, what
`python -m copilot_ray.sweep SPEC --check` reads for a spec with `resources.gpus_per_trial`), copied to
OUT/measured_throughput.json so that it comes back, and the depth_k plan on a GPU (sweeps/depth_k.yaml
with `gpus_per_trial: 0.5`, its `--check` wall-time line) as the last figure. `--record` puts a fetched
device_figures.json's GPU section into this checkout's measured_throughput.json (commit it with the
raw output under docs/throughput/).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
THROUGHPUT_FILE = REPO / "copilot_ray" / "measured_throughput.json"
GPU_RATES = "env_steps_per_s_gpu"  # copilot_ray.sweep_spec.estimate.GPU_RATES


@dataclass(frozen=True)
class Figure:
    key: str
    label: str
    step: str  # the script's step that measures it
    unit: str = ""
    target: str = ""
    gpu: bool = True  # measured only where torch sees a CUDA device


FIGURES = [
    Figure(
        "update_cpu_fused", "the SAC update alone on the CPU, fused eager", "trials", "updates/s", gpu=False
    ),
    Figure(
        "update_gpu_fused", "the SAC update alone on the GPU, fused eager", "trials", "updates/s", ">= 1,000"
    ),
    Figure(
        "update_gpu_captured",
        "the SAC update alone on the GPU, fused captured",
        "trials",
        "updates/s",
        ">= 1,000",
    ),
    Figure("captured_agrees", "captured against eager over 8 steps (largest parameter difference)", "trials"),
    Figure("stacked_update_1", "the stacked update, 1 seed, captured", "stacked_update", "seed-updates/s"),
    Figure("stacked_update_16", "the stacked update, 16 seeds, captured", "stacked_update", "seed-updates/s"),
    Figure("stacked_update_64", "the stacked update, 64 seeds, captured", "stacked_update", "seed-updates/s"),
    Figure(
        "trial_gpu",
        "one seed's CO-PILOT trial, learner on the GPU (two such trials sharing it)",
        "trials",
        "env steps/s per trial",
        ">= 700",
    ),
    Figure(
        "trial_gpu_without_eval", "the same, less its evaluation phase", "trials", "env steps/s per trial"
    ),
    Figure(
        "trial_cpu_twin",
        "its CPU twin beside it (2 CPUs; 1 on a small machine)",
        "trials",
        "env steps/s",
        gpu=False,
    ),
    Figure(
        "trial_cpu_twin_without_eval",
        "the same, less its evaluation phase",
        "trials",
        "env steps/s",
        gpu=False,
    ),
    Figure(
        "trial_cpu_before",
        "a CPU trial on the paths before the fused update",
        "trials",
        "env steps/s",
        gpu=False,
    ),
    Figure(
        "trial_gpu_lone",
        "one seed's trial alone on the GPU (stacked_trial.py's row: small trees, no evaluation)",
        "stacked_trial",
        "env steps/s",
        ">= 700",
    ),
    Figure(
        "stacked_16_trial",
        "16 stacked seeds in one CO-PILOT trial (the sweep's two trials sharing the GPU)",
        "sweep",
        "seed env steps/s per trial",
        ">= 8,000",
        gpu=False,  # the rehearsal's 2-seed cut measures its own stack on the CPU
    ),
    Figure(
        "stacked_64_trial",
        "64 stacked seeds in one CO-PILOT trial (stacked_trial.py)",
        "stacked_trial",
        "seed env steps/s",
        ">= 15,000",
    ),
    Figure(
        "update_gpu_compiled", "the SAC update alone on the GPU, compiled + captured", "compile", "updates/s"
    ),
    Figure("compiled_agrees", "compiled + captured against eager over 8 steps", "compile"),
    Figure("sweep", "the short stacked sweep: its trials, MLflow runs and archive", "pack", gpu=False),
    Figure("depth_k_gpu_plan", "depth_k's plan on the GPU (--check, gpus_per_trial 0.5)", "figures"),
]


def _lines(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text().splitlines():
        try:
            rows.append(json.loads(line))
        except ValueError:
            continue  # a line cut off mid-write
    return rows


def _sections(text: str) -> dict[str, list[str]]:
    """device_check.txt's lines per step (each step's output follows its `# step NAME ...` line)."""
    sections: dict[str, list[str]] = {}
    current = None
    for line in text.splitlines():
        m = re.match(r"# step (\S+)", line)
        if m:
            current = m.group(1)
            sections.setdefault(current, [])
        elif current is not None:
            sections[current].append(line)
    return sections


STACKED_UPDATE_ROW = re.compile(
    r"^(?P<name>one seed, fused|\d+ stacked(?:, captured)?)\s+(?P<rate>[\d.]+) updates/s\s+(?P<seed>[\d.]+) seed-updates/s"
)
STACKED_UPDATE_FAILED = re.compile(
    r"^(?P<name>one seed, fused|\d+ stacked(?:, captured)?)\s+failed: (?P<error>.*)"
)
STACKED_TRIAL_ROW = re.compile(r"^round \d+: (?P<name>.+?): (?P<rate>[\d.]+) env steps/s$")
STACKED_TRIAL_SO_FAR = re.compile(r"^\s+iteration (?P<i>\d+): (?P<rate>[\d.]+) env steps/s so far")
STACKED_TRIAL_WARM = re.compile(r"^\s+warm-up iteration: .* in (?P<s>\d+) s")


def stacked_update_rows(lines: list[str]) -> dict[str, tuple[float, float] | str]:
    rows: dict[str, tuple[float, float] | str] = {}
    for line in lines:
        if m := STACKED_UPDATE_ROW.match(line):
            rows[m["name"]] = (float(m["rate"]), float(m["seed"]))
        elif m := STACKED_UPDATE_FAILED.match(line):
            rows[m["name"]] = m["error"]
    return rows


# The rows the check's stacked_trial step prints, in order (`--stacks 64`).
STACKED_TRIAL_ORDER = ["one seed, its own trial", "64 seeds in one trial, one stacked update"]


def stacked_trial_rows(lines: list[str], order: list[str] = STACKED_TRIAL_ORDER) -> dict[str, dict]:
    """stacked_trial.py's rows, met in `order`: a finished row's rate; a row cut off keeps its last
    running rate ('so far') and how long its warm-up iteration took, if it finished one."""
    rows: dict[str, dict] = {}
    current = 0
    for line in lines:
        name = order[current] if current < len(order) else None
        if m := STACKED_TRIAL_ROW.match(line):
            rows[m["name"]] = {"rate": float(m["rate"]), "done": True}
            current += 1
        elif name and (m := STACKED_TRIAL_WARM.match(line)):
            rows.setdefault(name, {})["warm_s"] = float(m["s"])
        elif name and (m := STACKED_TRIAL_SO_FAR.match(line)):
            rows.setdefault(name, {}).update(rate=float(m["rate"]), iterations=int(m["i"]), done=False)
    return rows


def _fmt(value: float) -> str:
    return f"{value:,.0f}" if value >= 100 else f"{value:.1f}"


class Reader:
    """What one check left in OUT, and each figure's line from it."""

    def __init__(self, out: Path):
        self.out = out
        self.steps = {s["step"]: s for s in _lines(out / "steps.jsonl")}
        self.figures = _lines(out / "figures.jsonl")
        text = (out / "device_check.txt").read_text() if (out / "device_check.txt").is_file() else ""
        self.sections = _sections(text)
        self.cuda = any(s.get("cuda") for s in self.steps.values()) or "cuda: yes" in text[:2000]
        self.trials = self._trials()

    def _trials(self) -> dict[str, dict]:
        sys.path.insert(0, str(REPO / "benchmarks"))
        try:
            import device_throughput
        except ImportError:  # its import of benchmarks/throughput.py needs nothing beyond the stdlib
            return {}
        log = self.out / "trials.jsonl"
        if not log.is_file():
            return {}
        by_trial, _, errors = device_throughput.read_log(str(log))
        kinds: dict[str, dict] = {}
        for (kind, _), records in by_trial.items():
            r = device_throughput.rates(records)
            entry = kinds.setdefault(kind, {"rates": [], "without": [], "errors": [], "iterations": 0})
            entry["iterations"] = max(entry["iterations"], len(records))
            if r is not None:
                entry["rates"].append(r["env_steps_per_s"])
                if r["env_steps_per_s_without_eval"]:
                    entry["without"].append(r["env_steps_per_s_without_eval"])
        for (kind, _), error in errors.items():
            kinds.setdefault(kind, {"rates": [], "without": [], "errors": [], "iterations": 0})[
                "errors"
            ].append(error)
        return kinds

    def why_not(self, figure: Figure) -> str:
        """The line for a figure that has no value: from its step's record."""
        step = self.steps.get(figure.step)
        if figure.gpu and not self.cuda:
            return "skipped: no CUDA device"
        if step is None:
            return "not reached (its step did not run)"
        if step.get("skipped"):
            return f"not reached ({step['skipped']})"
        if step.get("rc") in (124, 137):
            return f"not reached (cut at {step['cap_s']} s)"
        if step.get("rc"):
            return f"not reached (step {figure.step} exited {step['rc']} after {step.get('seconds', '?')} s)"
        return "not reached (its step ended without it)"

    def value(self, f: Figure) -> tuple[float | None, str | None]:
        """(value, text) of a figure, or (None, None) when there is none."""
        update = {(r["device"], r["path"]): r for r in self.figures if r.get("figure") == "update alone"}
        agree = {r["path"]: r for r in self.figures if r.get("figure") == "agreement"}
        if f.key.startswith("update_"):
            device, path = {
                "update_cpu_fused": ("cpu", "fused eager"),
                "update_gpu_fused": ("cuda", "fused eager"),
                "update_gpu_captured": ("cuda", "fused captured"),
                "update_gpu_compiled": ("cuda", "fused compiled + captured"),
            }[f.key]
            r = update.get((device, path))
            if r is None:
                return None, None
            if "error" in r:
                return None, f"failed: {r['error']}"
            return r["updates_per_s"], f"{_fmt(r['updates_per_s'])} {f.unit} (warm-up {r['warm_s']:.1f} s)"
        if f.key in ("captured_agrees", "compiled_agrees"):
            r = agree.get("fused captured" if f.key == "captured_agrees" else "fused compiled + captured")
            if r is None:
                return None, None
            if "error" in r:
                return None, f"failed: {r['error']}"
            verdict = "agrees" if r["agrees"] else "DISAGREES"
            return r[
                "largest_difference"
            ], f"{verdict} (largest parameter difference {r['largest_difference']:.2e})"
        if f.key.startswith("stacked_update_"):
            n = f.key.rsplit("_", 1)[1]
            rows = stacked_update_rows(self.sections.get("stacked_update", []))
            r = rows.get(f"{n} stacked, captured")
            if isinstance(r, str):
                return None, f"failed: {r}"
            if r is None:
                return None, None
            eager = rows.get(f"{n} stacked")
            extra = f"; eager {_fmt(eager[1])}" if isinstance(eager, tuple) else ""
            return r[1], f"{_fmt(r[1])} {f.unit} ({_fmt(r[0])} stacked updates/s{extra})"
        if f.key.startswith("trial_") and f.key != "trial_gpu_lone":
            kind = {"trial_gpu": "gpu", "trial_cpu_twin": "cpu baseline", "trial_cpu_before": "cpu before"}[
                f.key.removesuffix("_without_eval")
            ]
            entry = self.trials.get(kind)
            if entry is None:
                return None, None
            values = entry["without" if f.key.endswith("_without_eval") else "rates"]
            if not values:
                if entry["errors"]:
                    return None, f"failed: {entry['errors'][0]}"
                return None, None
            mean = sum(values) / len(values)
            note = f" ({len(values)} trial(s); {len(entry['errors'])} failed)" if entry["errors"] else ""
            return mean, f"{_fmt(mean)} {f.unit}{note}"
        if f.key in ("trial_gpu_lone", "stacked_64_trial"):
            rows = stacked_trial_rows(self.sections.get("stacked_trial", []))
            name = (
                "one seed, its own trial"
                if f.key == "trial_gpu_lone"
                else "64 seeds in one trial, one stacked update"
            )
            r = rows.get(name)
            if r is None or "rate" not in r:
                if r and "warm_s" in r:
                    return None, f"{self.why_not(f)}; its warm-up iteration took {r['warm_s']:.0f} s"
                return None, None
            cut = "" if r.get("done") else f" (so far: {r['iterations']} iteration(s) when cut)"
            return r["rate"], f"{_fmt(r['rate'])} {f.unit}{cut}"
        if f.key == "stacked_16_trial":
            rows = [r for r in self.figures if r.get("source") == "device_sweep"]
            rates = [r["seed_env_steps_per_s"] for r in rows if r.get("seed_env_steps_per_s")]
            if not rates:
                return None, None
            seeds = rows[0]["seeds"]
            label = f" ({len(rates)} trial(s) of {seeds} seeds{'' if seeds == 16 else ': the CPU cut'})"
            return sum(rates) / len(rates), f"{_fmt(sum(rates) / len(rates))} {f.unit}{label}"
        if f.key == "sweep":
            lines = self.sections.get("pack", [])
            archive = self.out / "device_sweep.tar.gz"
            states = [line for line in lines if re.match(r"^\S+: (finished|unfinished|not started)", line)]
            if not archive.is_file():
                return None, None
            return archive.stat().st_size, (
                f"{'; '.join(states) or 'its state unknown'}; archive {archive.stat().st_size / 2**20:.1f} MiB in OUT"
            )
        if f.key == "depth_k_gpu_plan":
            line = getattr(self, "depth_k_line", None)
            return (None, line) if line else (None, None)
        return None, None

    def lines(self) -> tuple[list[str], list[dict]]:
        out, records = [], []
        for f in FIGURES:
            value, text = self.value(f)
            if text is None:
                text = self.why_not(f)
            target = f" [target {f.target}]" if f.target and value is not None and self.cuda else ""
            out.append(f"figure {f.key}: {f.label}: {text}{target}")
            records.append({"key": f.key, "label": f.label, "value": value, "unit": f.unit, "line": text})
        return out, records


def gpu_section(reader: Reader, commit: str, machine: str) -> dict | None:
    """The GPU section of measured_throughput.json from this check, or None without a GPU trial rate."""
    entry = reader.trials.get("gpu")
    if not reader.cuda or not entry or not entry["rates"]:
        return None
    rate = sum(entry["rates"]) / len(entry["rates"])
    without = sum(entry["without"]) / len(entry["without"]) if entry["without"] else None
    day = time.strftime("%Y-%m-%d")
    how = (
        f"scripts/device_check.sh at {commit} on {day}: benchmarks/device_throughput.py, two CO-PILOT trials "
        "sharing the GPU, 2 CPUs each, tree_depth 3 (shorter iterations than the default 5; env steps/s hardly "
        "depend on it), evaluation every 3200 env steps on 100 validation + 100 test tasks"
    )
    section = {
        "what": "env steps per second of one trial with its learner on a GPU, on maze-point four-rooms (one SAC "
        "update per env step): two trials sharing one GPU (`side_by_side`); what `--check` reads for a spec "
        "with resources.gpus_per_trial",
        "machine": machine,
        "source": how,
        "env_steps_per_s": {"copilot": {"side_by_side": round(rate)}},
        "sources": {"copilot.side_by_side": how},
    }
    if without:
        section["without_evaluation"] = {"copilot": {"side_by_side": round(without)}}
    return section


def merge_gpu_section(section: dict, path: Path | None = None) -> None:
    path = path or THROUGHPUT_FILE
    data = json.loads(path.read_text())
    old = data.get(GPU_RATES, {})
    rates = {**old.get("env_steps_per_s", {})}
    for algorithm, slots in section["env_steps_per_s"].items():
        rates[algorithm] = {**rates.get(algorithm, {}), **slots}
    data[GPU_RATES] = {
        **old,
        **section,
        "env_steps_per_s": rates,
        "sources": {**old.get("sources", {}), **section["sources"]},
    }
    path.write_text(json.dumps(data, indent=2) + "\n")


def depth_k_plan(python: str = sys.executable) -> str | None:
    """The wall-time line of sweeps/depth_k.yaml's plan with its learners on half a GPU each."""
    import yaml

    data = yaml.safe_load((REPO / "sweeps" / "depth_k.yaml").read_text())
    data["resources"] = {**data["resources"], "gpus_per_trial": 0.5}
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "depth_k_gpu.yaml"
        spec.write_text(yaml.safe_dump(data, sort_keys=False))
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
        done = subprocess.run(
            [python, "-m", "copilot_ray.sweep", str(spec), "--check"],
            capture_output=True,
            text=True,
            cwd=tmp,
            env=env,
            timeout=120,
        )
    wall = [line.strip() for line in done.stdout.splitlines() if line.strip().startswith("wall time:")]
    return wall[0] if wall else f"failed: --check exited {done.returncode}: {done.stderr.strip()[-200:]}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python3 benchmarks/device_figures.py", description=__doc__.split("\n\n")[0]
    )
    p.add_argument("out", type=Path, nargs="?", help="the check's folder ($OUT)")
    p.add_argument(
        "--write", action="store_true", help="the GPU section into measured_throughput.json, and the plan"
    )
    p.add_argument(
        "--record", type=Path, default=None, metavar="OUT", help="a fetched folder's GPU section, here"
    )
    args = p.parse_args(argv)
    if args.record is not None:
        data = json.loads((args.record / "device_figures.json").read_text())
        if not data.get("gpu_section"):
            print(f"{args.record}: no GPU trial rate to record (device_figures.json has no gpu_section)")
            return 1
        merge_gpu_section(data["gpu_section"])
        print(f"recorded {GPU_RATES} from {args.record} (commit {data.get('commit')}) in {THROUGHPUT_FILE}")
        return 0
    if args.out is None:
        p.error("give OUT, or --record OUT")
    reader = Reader(args.out)
    head = (
        (args.out / "device_check.txt").read_text().splitlines()[:1]
        if (args.out / "device_check.txt").is_file()
        else []
    )
    commit = os.environ.get("COMMIT") or _git_commit()
    machine = os.environ.get("DEVICE_MACHINE", head[0].lstrip("# ") if head else "?")
    section = gpu_section(reader, commit, machine)
    if args.write and section is not None:
        merge_gpu_section(section)
        (args.out / "measured_throughput.json").write_text(THROUGHPUT_FILE.read_text())
        reader.depth_k_line = depth_k_plan()
    elif args.write:
        reader.depth_k_line = None
    lines, records = reader.lines()
    print("\n".join(lines))
    (args.out / "device_figures.json").write_text(
        json.dumps(
            {"commit": commit, "machine": machine, "figures": records, "gpu_section": section}, indent=1
        )
        + "\n"
    )
    return 0


def _git_commit() -> str:
    try:
        return subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


if __name__ == "__main__":
    raise SystemExit(main())
