"""The GPU check's short stacked sweep (sweeps/device_stacked.yaml): where it runs, how fast its seeds
stepped, and how its store comes back to another machine and resumes there.

    python3 benchmarks/device_sweep.py prepare ROOT [--cpu]    # ROOT/device_stacked.yaml (ROOT: new)
    python3 benchmarks/device_sweep.py rate ROOT [--figures FILE]  # seed env steps/s of its trials so far
    python3 benchmarks/device_sweep.py pack ROOT ARCHIVE [--figures FILE]   # carry, and the rates
    python3 benchmarks/device_sweep.py unpack ARCHIVE           # a packed store back at its ROOT

`prepare` writes the spec into ROOT, the folder the sweep is started from (`cd ROOT && python3 -m
copilot_ray.sweep device_stacked.yaml`, with this checkout on PYTHONPATH): its results go to
ROOT/results. Tune's state names absolute paths, so a store resumes only at the path it was begun at,
and ROOT is one both machines have (scripts/device_check.sh: /tmp/copilot_device_sweep on a GPU,
/tmp/copilot_device_sweep_cpu for a rehearsal). `--cpu`: the same file for a machine without a GPU, cut
to 2 stacked seeds, 1 CPU a trial, one trial at a time and 2 iterations (a rehearsal's, and the tests').

`rate` reads each trial's Tune results (ROOT/results/device_stacked/tune/...): the seed env steps (all its
seeds) per second over the iterations after the first (the first builds every seed and warms its
planner up), and how long that first one took; a trial with a single iteration has no rate.

`pack` packs the sweep's results by `python -m copilot_ray.carry` into ARCHIVE; when that is over
PACK_LIMIT (a file comes back from a device call at 16 MiB at most; an experiment in flight carries its
unfinished trials' checkpoints, 16 seeds' replay buffers among them) it packs again `--report-only`
(the store and small artifacts, no Tune folders) and says so. Then it prints the rates (and appends them
to --figures). Its exit status is carry's.

`unpack` extracts an archive of `python -m copilot_ray.carry` into the ROOT its carry.json names (refused
when ROOT/results exists) and writes ROOT/device_stacked.yaml from the resolved copy inside, so that
`cd ROOT && python -m copilot_ray.sweep device_stacked.yaml --resume` continues it at the commit it was
packed at. Tune keeps each trial's resources in its state: trials begun on a GPU continue on a machine
with one; here a GPU store's finished runs are read (`python -m copilot_ray.progress`, `analysis.report`).
"""

from __future__ import annotations

import argparse
import json
import sys
import tarfile
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
SPEC = REPO / "sweeps" / "device_stacked.yaml"
NAME = "device_stacked"
CPU = {  # what a machine without a GPU runs of the same file
    "seeds": [0, 1],
    "seeds_per_trial": 2,
    "stop": {"iterations": 2, "min_evaluations": 1},
    "resources": {"max_concurrent_trials": 1, "num_env_runners": 0, "cpus_per_trial": 1, "gpus_per_trial": 0},
    "fault_tolerance": {"checkpoint_every": 1},
}
CPU_CONFIG = {"eval_interval": 2}


def prepare(root: Path, cpu: bool = False, overrides: dict | None = None) -> Path:
    """ROOT/device_stacked.yaml, the GPU spec or its CPU cut (`overrides`: top-level keys replaced)."""
    if (root / "results").exists():
        raise SystemExit(f"error: {root / 'results'} exists: a sweep began there already (remove it first)")
    data = yaml.safe_load(SPEC.read_text())
    if cpu:
        data.update(CPU)
        data["config"] = {**data["config"], **CPU_CONFIG}
        data["description"] = (
            "GPU check's sweep cut for a machine without a GPU: 2 stacked seeds, 2 iterations."
        )
    data.update(overrides or {})
    root.mkdir(parents=True, exist_ok=True)
    path = root / f"{NAME}.yaml"
    path.write_text(
        f"# {SPEC.relative_to(REPO)} as benchmarks/device_sweep.py prepare{' --cpu' if cpu else ''} wrote it\n"
        + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110)
    )
    return path


def trial_rates(root: Path) -> list[dict]:
    """Per Tune trial of the sweep under ROOT: its seeds, iterations, seed env steps/s after the first."""
    from copilot_ray import keys

    rows = []
    for results in sorted((root / "results" / NAME / "tune").glob("*/*/result.json")):
        records = [json.loads(line) for line in results.read_text().splitlines() if line.strip()]
        if not records:
            continue

        def steps(record: dict) -> float:
            seeds = record.get(keys.SEED_RESULTS) or {}
            if seeds:
                return float(sum(m.get(keys.ENV_STEPS, 0.0) for m in seeds.values()))
            return float(keys.result_value(record, keys.ENV_STEPS) or 0.0)

        later = records[1:]
        wall = sum(float(r.get("time_this_iter_s", 0.0)) for r in later)
        rate = (steps(records[-1]) - steps(records[0])) / wall if later and wall > 0 else None
        seeds = records[-1].get(keys.SEED_RESULTS) or {}
        rows.append(
            {
                "trial": results.parent.name,
                "config": records[-1].get("config", {}).get("tree_depth"),
                "seeds": len(seeds) or 1,
                "iterations": len(records),
                "first_iteration_s": float(records[0].get("time_this_iter_s", 0.0)),
                "seed_env_steps_per_s": rate,
                "done": bool(records[-1].get("done")),
            }
        )
    return rows


def rate_lines(rows: list[dict]) -> list[str]:
    if not rows:
        return ["device sweep: no trial reported an iteration"]
    lines = []
    for r in rows:
        rate = (
            f"{r['seed_env_steps_per_s']:.0f} seed env steps/s"
            if r["seed_env_steps_per_s"]
            else "no rate yet"
        )
        lines.append(
            f"device sweep trial {r['trial']} (tree_depth {r['config']}, {r['seeds']} seeds): {rate} over "
            f"{r['iterations'] - 1} iteration(s) after a first of {r['first_iteration_s']:.0f} s"
            + ("" if r["done"] else " (not finished)")
        )
    return lines


PACK_LIMIT = 15 * 2**20


def pack(root: Path, archive: Path, limit: int = PACK_LIMIT) -> int:
    from copilot_ray import carry

    spec = root / f"{NAME}.yaml"
    code = carry.main([str(spec), str(archive), "--root", str(root)])
    if code == 0 and archive.stat().st_size > limit:
        print(
            f"{archive} is {archive.stat().st_size / 2**20:.1f} MiB, over the {limit / 2**20:.0f} MiB a file comes "
            "back with: packed again --report-only (the store and small artifacts; no Tune folders)"
        )
        code = carry.main([str(spec), str(archive), "--root", str(root), "--report-only"])
    return code


def unpack(archive: Path) -> Path:
    root, _ = unpack_with_parts(archive)
    return root


def unpack_with_parts(archive: Path) -> tuple[Path, dict[str, str]]:
    """(the root it went back to, each part's state as packed: finished, unfinished, not started)."""
    with tarfile.open(archive) as tar:
        manifest = next((m for m in tar.getmembers() if m.name.endswith("/carry.json")), None)
        if manifest is None:
            raise SystemExit(f"error: {archive} holds no carry.json: not an archive of copilot_ray.carry")
        packed = json.loads(tar.extractfile(manifest).read())
        root = Path(packed["root"])
        if (root / "results").exists():
            raise SystemExit(f"error: {root / 'results'} exists: move it aside to unpack {archive} there")
        root.mkdir(parents=True, exist_ok=True)
        tar.extractall(root, filter="data")
    resolved = root / "results" / NAME / "spec.yaml"
    (root / f"{NAME}.yaml").write_text(resolved.read_text())
    return root, packed.get("parts", {})


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python3 benchmarks/device_sweep.py", description=__doc__.split("\n\n")[0]
    )
    sub = p.add_subparsers(dest="command", required=True)
    a = sub.add_parser("prepare", help="write ROOT/device_stacked.yaml")
    a.add_argument("root", type=Path)
    a.add_argument("--cpu", action="store_true", help="the cut for a machine without a GPU")
    b = sub.add_parser("rate", help="seed env steps/s of the sweep's trials under ROOT")
    b.add_argument("root", type=Path)
    b.add_argument(
        "--figures",
        type=Path,
        default=None,
        help="append the rows as JSON lines (benchmarks/device_figures.py)",
    )
    d = sub.add_parser("pack", help="carry the sweep under ROOT into ARCHIVE (--report-only when too large)")
    d.add_argument("root", type=Path)
    d.add_argument("archive", type=Path)
    d.add_argument("--figures", type=Path, default=None, help="append the trials' rates as JSON lines")
    c = sub.add_parser("unpack", help="a packed store back at the ROOT it was packed from")
    c.add_argument("archive", type=Path)
    args = p.parse_args(argv)
    if args.command == "prepare":
        print(prepare(args.root.resolve(), args.cpu))
    elif args.command in ("rate", "pack"):
        code = pack(args.root.resolve(), args.archive.resolve()) if args.command == "pack" else 0
        rows = trial_rates(args.root.resolve())
        print("\n".join(rate_lines(rows)))
        if args.figures:
            with open(args.figures, "a") as f:
                f.writelines(json.dumps({"source": "device_sweep", **row}) + "\n" for row in rows)
        return code
    else:
        root, parts = unpack_with_parts(args.archive)
        python = f"PYTHONPATH={REPO} {sys.executable}"
        print(f"unpacked {args.archive} into {root}: " + ", ".join(f"{k} {v}" for k, v in parts.items()))
        if any(state != "finished" for state in parts.values()):
            print(f"resume: cd {root} && {python} -m copilot_ray.sweep {NAME}.yaml --resume")
        else:
            print(
                f"finished: nothing to resume; read it: {python} -m copilot_ray.progress {root / NAME}.yaml --root {root}"
            )
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    raise SystemExit(main())
