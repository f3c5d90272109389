"""Fault drills: a small real sweep on local Ray, a process killed with SIGKILL in the middle, and what
MLflow and Tune hold afterwards.

    PYTHONPATH=. python benchmarks/fault_drills.py [--drills driver trial] [--iterations 6] [--keep DIR]

Without --keep the drills work in a new folder in the system's temp folder and remove it at the end.

Drills (each on its own copy of the smoke sweep: two trials, tree depth 1 and 2, one at a time,
`--iterations` iterations each, a checkpoint every iteration):

* driver: SIGKILL the sweep driver and every process it started (Ray's too) once the first trial has 3
  results, then `python -m copilot_ray.sweep SPEC --resume` to the end.
* driver_her: the driver drill on the HER baseline (seeds 0 and 1 of the smoke sweep's env): the trials
  resume with their relabelling replay buffers.
* driver_optuna: the same with an Optuna searcher (3 samples of tree depth 1 or 2); also checks that the
  study holds 3 COMPLETE trials and no other.
* trial: SIGKILL the first trial's worker process (the pid in its results) once it has 3 results; Tune
  retries it from its last checkpoint (FailureConfig) and the sweep ends by itself.
* runner: the smoke sweep with one env runner per trial; SIGKILL that runner's process at a random
  moment (`--kill-seed`) of the first trial's 3rd iteration: Ray restarts the actor, CO-PILOT counts the sub-tasks the runner took with it
  (`copilot/agent/subtasks_lost`, printed) and the trial goes on without a Tune retry.
* driver_stacked: one configuration, seeds 0, 1 and 2 stacked in one trial (`seeds_per_trial: 3`) and
  `COPILOT_RAY_FAULT=planner_nan@3:seed=1`; SIGKILL the driver at the trial's 4th result, then
  `--resume` to the end: seeds 0 and 2 must each have one FINISHED run with every iteration once, seed 1
  one FAILED run naming the non-finite planner (it stops alone, the others go on).
* nan: one configuration, seeds 0 and 1, and `COPILOT_RAY_FAULT=planner_nan@3:seed=1` (NaN into seed 1's
  planner weights at iteration 3; copilot_ray/planning/health.py): seed 1 must stop with the
  reason in the console and in its MLflow run (FAILED, tag copilot.error) after its retries, seed 0 must
  finish; "lost" counts only runs that should have finished.

Each prints "drill NAME: runs lost L, duplicated D, restarted from scratch S" (all 0 when nothing was
lost) with what it checked: every planned trial has exactly one MLflow run, FINISHED, whose iterations
1..N each appear once and whose env steps only grow; the parent run is closed; a trial that had a
checkpoint never started again at iteration 1 (Tune's result.json of that trial has one first iteration).
Exit status 1 when a drill found anything lost, duplicated or restarted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import yaml

from copilot_ray.keys import SUCCESS_PLANNED, validation_key

ROOT = Path(__file__).resolve().parents[1]


def write_spec(directory: Path, name: str, iterations: int, **changes) -> Path:
    """The smoke sweep with `changes` (a value None removes its key)."""
    data = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())
    data.update(name=name, tracking={"storage": str(directory / "results")}, stop={"iterations": iterations})
    data.update(changes)
    data = {k: v for k, v in data.items() if v is not None}
    path = directory / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def sweep(spec: Path, *args: str, env_extra: dict | None = None) -> subprocess.Popen:
    env = {**os.environ, "RAY_AUTH_MODE": "disabled", "PYTHONPATH": str(ROOT), **(env_extra or {})}
    log = open(spec.with_suffix(f".{int(time.time())}.log"), "w")  # noqa: SIM115 - lives with the process
    return subprocess.Popen(
        [sys.executable, "-m", "copilot_ray.sweep", str(spec), *args],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
        start_new_session=True,
    )


def result_rows(root: Path) -> dict[str, list[dict]]:
    """Tune's result.json rows per trial folder."""
    out = {}
    for f in sorted(root.rglob("result.json")):
        rows = []
        for line in f.read_text().splitlines():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:  # a line being written
                pass
        out[f.parent.name] = rows
    return out


def wait_for_results(root: Path, count: int, proc: subprocess.Popen, timeout: float = 600) -> list[dict]:
    """The first trial's rows once it has `count` results."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        trials = result_rows(root)
        if trials:
            first = trials[min(trials)]
            if len(first) >= count:
                return first
        if proc.poll() is not None:
            raise RuntimeError(f"the sweep ended (rc {proc.returncode}) before the kill")
        time.sleep(0.5)
    raise TimeoutError("no results in time")


def descendants(pid: int) -> list[int]:
    """Every process below `pid` (Linux: read from /proc; Ray's daemons included, which start their own
    sessions but stay children of the driver)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def kill_tree(pid: int) -> int:
    """SIGKILL a process and every process it started (gathered first, then all at once)."""
    procs = [*descendants(pid), pid]
    for p in procs:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    time.sleep(2)
    return len(procs)


def audit(spec_path: Path, iterations: int, failing_seeds: tuple[str, ...] = ()) -> dict[str, int]:
    """Lost / duplicated / restarted counts from MLflow and Tune's files, with a line per finding.
    Trials of `failing_seeds` are expected to end FAILED with a reason instead of finishing."""
    import mlflow

    from copilot_ray.keys import (
        ENV_STEPS,
        ERROR_TAG,
        ROLE_SWEEP,
        ROLE_TAG,
        ROLE_TRIAL,
        SEED_TAG,
        TRAINING_ITERATION,
        TRIAL_ID_TAG,
    )
    from copilot_ray.sweep_spec import load_spec

    spec = load_spec(spec_path)
    client = mlflow.MlflowClient(spec.tracking.uri)
    exp = client.get_experiment_by_name(spec.experiment)
    runs = client.search_runs([exp.experiment_id], max_results=1000)
    parents = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_SWEEP]
    children = [r for r in runs if r.data.tags.get(ROLE_TAG) == ROLE_TRIAL]
    found = {"lost": 0, "duplicated": 0, "restarted": 0}
    failing = [r for r in children if r.data.tags.get(SEED_TAG) in failing_seeds]
    for run in failing:
        reason = run.data.tags.get(ERROR_TAG, "")
        print(f"  run {run.info.run_name}: {run.info.status}, copilot.error = {reason!r}")
        if run.info.status != "FAILED" or "non-finite" not in reason:
            found["lost"] += 1
    children = [r for r in children if r not in failing]
    planned = len(spec.trial_plan()) * spec.seeds_per_trial - len(failing_seeds)
    by_trial: dict[tuple[str, str], list] = {}  # (trial, seed): a stacked trial has a run per seed
    for run in children:
        by_trial.setdefault((run.data.tags[TRIAL_ID_TAG], run.data.tags[SEED_TAG]), []).append(run)
    finished = [r for r in children if r.info.status == "FINISHED"]
    found["lost"] += planned - len({(r.data.tags[TRIAL_ID_TAG], r.data.tags[SEED_TAG]) for r in finished})
    if len(failing) != len(failing_seeds):
        print(f"  {len(failing)} run(s) of the failing seeds {failing_seeds}, expected one each")
        found["lost" if len(failing) < len(failing_seeds) else "duplicated"] += 1
    found["duplicated"] += sum(len(v) - 1 for v in by_trial.values()) + max(0, len(parents) - 1)
    if not parents or parents[0].info.status not in ("FINISHED", "FAILED" if failing_seeds else "FINISHED"):
        print(f"  parent run not closed: {[p.info.status for p in parents]}")
        found["lost"] += 1
    for run in children:
        iters = [int(m.value) for m in client.get_metric_history(run.info.run_id, TRAINING_ITERATION)]
        steps = [m.step for m in client.get_metric_history(run.info.run_id, ENV_STEPS)]
        if sorted(iters) != list(range(1, iterations + 1)):
            print(f"  run {run.info.run_name}: iterations {sorted(iters)}")
            found["duplicated" if len(iters) > len(set(iters)) else "lost"] += 1
        if steps != sorted(set(steps)):
            print(f"  run {run.info.run_name}: env steps not strictly growing {steps}")
            found["duplicated"] += 1
    for trial, rows in result_rows(Path(spec.tracking.storage) / spec.name / "tune").items():
        if any(str(r.get("config", {}).get("seed")) in failing_seeds for r in rows[:1]):
            continue  # retried from its checkpoint by design
        starts = sum(1 for r in rows if r.get("training_iteration") == 1)
        if starts > 1:
            print(f"  trial {trial}: started at iteration 1 {starts} times")
            found["restarted"] += 1
    return found


def kill_driver_then_resume(
    spec: Path, tune_dir: Path, at: int = 3, env_extra: dict | None = None, exit_codes: tuple[int, ...] = (0,)
) -> None:
    """Start the sweep, SIGKILL its driver and everything it started at the first trial's `at`-th
    result, then run `--resume` to the end (which must exit with one of `exit_codes`)."""
    proc = sweep(spec, env_extra=env_extra)
    rows = wait_for_results(tune_dir, at, proc)
    killed = kill_tree(proc.pid)
    print(f"  killed the driver and {killed - 1} processes it started after iteration {len(rows)}")
    resumed = sweep(spec, "--resume", env_extra=env_extra)
    if resumed.wait(timeout=900) not in exit_codes:
        raise RuntimeError(f"--resume exited {resumed.returncode} (log next to {spec})")


def spec_driver(directory: Path, iterations: int) -> Path:
    return write_spec(directory, "drill_driver", iterations)


def drill_driver(directory: Path, iterations: int) -> dict[str, int]:
    spec = spec_driver(directory, iterations)
    kill_driver_then_resume(spec, directory / "results" / "drill_driver" / "tune")
    return audit(spec, iterations)


def spec_driver_her(directory: Path, iterations: int) -> Path:
    """The smoke sweep on the HER baseline, seeds 0 and 1."""
    return write_spec(
        directory,
        "drill_her",
        iterations,
        algorithm="her",
        config={
            "tau_max": 50,
            "task_batch_size": 4,
            "eval_interval": 1,
            "eval_num_tasks": 10,
            "num_steps_sampled_before_learning_starts": 256,
        },
        search=None,
        seeds=[0, 1],
    )


def drill_driver_her(directory: Path, iterations: int) -> dict[str, int]:
    """The driver drill on the HER baseline, seeds 0 and 1: its relabelling buffer is in the checkpoint."""
    spec = spec_driver_her(directory, iterations)
    kill_driver_then_resume(spec, directory / "results" / "drill_her" / "tune")
    return audit(spec, iterations)


def spec_driver_hrl(directory: Path, iterations: int) -> Path:
    """The smoke sweep on the HIRO-style hierarchy, seeds 0 and 1."""
    return write_spec(
        directory,
        "drill_hrl",
        iterations,
        algorithm="hrl",
        config={
            "tau_max": 50,
            "task_batch_size": 4,
            "env_steps_per_iteration": 200,
            "eval_interval": 1,
            "eval_num_tasks": 10,
            "num_steps_sampled_before_learning_starts": 200,
        },
        search=None,
        seeds=[0, 1],
    )


def drill_driver_hrl(directory: Path, iterations: int) -> dict[str, int]:
    """The driver drill on the HIRO-style hierarchy (a plain Tune Trainable with its own env loop),
    seeds 0 and 1: both levels' learners and replays are in its checkpoint."""
    spec = spec_driver_hrl(directory, iterations)
    kill_driver_then_resume(spec, directory / "results" / "drill_hrl" / "tune")
    return audit(spec, iterations)


def spec_driver_optuna(directory: Path, iterations: int) -> Path:
    """The smoke sweep searched by Optuna (3 samples of tree depth 1 or 2) on a validation metric: a
    searcher may not look at the test tasks (the spec check refuses it)."""
    return write_spec(
        directory,
        "drill_optuna",
        iterations,
        search={"tree_depth": {"categorical": [1, 2]}},
        searcher={
            "type": "optuna",
            "metric": validation_key(SUCCESS_PLANNED),
            "mode": "max",
            "num_samples": 3,
            "seed": 0,
        },
    )


def drill_driver_optuna(directory: Path, iterations: int) -> dict[str, int]:
    import optuna

    spec = spec_driver_optuna(directory, iterations)
    kill_driver_then_resume(spec, directory / "results" / "drill_optuna" / "tune")
    found = audit(spec, iterations)
    storage = f"sqlite:///{directory / 'results' / 'drill_optuna' / 'optuna.db'}"
    (summary,) = optuna.get_all_study_summaries(storage)
    states = [t.state.name for t in optuna.load_study(study_name=summary.study_name, storage=storage).trials]
    print(f"  Optuna study {summary.study_name}: {states}")
    found["lost"] += max(0, 3 - states.count("COMPLETE"))
    found["duplicated"] += max(0, len(states) - 3)
    return found


def spec_trial(directory: Path, iterations: int) -> Path:
    return write_spec(directory, "drill_trial", iterations)


def drill_trial(directory: Path, iterations: int) -> dict[str, int]:
    spec = spec_trial(directory, iterations)
    proc = sweep(spec)
    rows = wait_for_results(directory / "results" / "drill_trial" / "tune", 3, proc)
    pid = int(rows[-1]["pid"])
    os.kill(pid, signal.SIGKILL)
    print(f"  killed trial process {pid} after iteration {len(rows)}")
    if proc.wait(timeout=900) != 0:
        raise RuntimeError(
            f"the sweep exited {proc.returncode} after the trial was killed (log next to {spec})"
        )
    return audit(spec, iterations)


KILL_SEED = 0  # set by --kill-seed


def spec_runner(directory: Path, iterations: int) -> Path:
    """The smoke sweep with one env runner per trial and one sub-task per sampling round: many rounds
    per iteration, so the kill lands inside one."""
    config = yaml.safe_load((ROOT / "sweeps" / "smoke.yaml").read_text())["config"]
    config["subtasks_per_sample"] = 1
    return write_spec(directory, "drill_runner", iterations, resources={"num_env_runners": 1}, config=config)


def drill_runner(directory: Path, iterations: int) -> dict[str, int]:
    import mlflow

    from copilot_ray.keys import AGENT_SUBTASKS_LOST
    from copilot_ray.sweep_spec import load_spec

    spec = spec_runner(directory, iterations)
    proc = sweep(spec)
    rows = wait_for_results(directory / "results" / "drill_runner" / "tune", 2, proc)
    # Anywhere in the next iteration (checkpoint, sampling, updates, weight sync, evaluation): a delay
    # drawn from --kill-seed within the 2nd iteration's length, so repeated drills hit different moments.
    iteration_s = float(rows[-1].get("time_this_iter_s", 3.0))
    delay = random.Random(KILL_SEED).uniform(0.0, iteration_s)
    time.sleep(delay)
    runners = [p for p in descendants(proc.pid) if "EnvRunner" in _cmdline(p)]
    if not runners:
        proc.terminate()  # do not leave the sweep running behind a failed drill
        proc.wait(timeout=120)
        raise RuntimeError("no env runner process found under the sweep driver")
    os.kill(runners[0], signal.SIGKILL)
    print(
        f"  killed env runner process {runners[0]} {delay:.1f} s into the 3rd iteration ({iteration_s:.1f} s long)"
    )
    if proc.wait(timeout=900) != 0:
        raise RuntimeError(f"the sweep exited {proc.returncode} (log next to {spec})")
    found = audit(spec, iterations)
    log = max(directory.glob("drill_runner.*.log")).read_text()
    if "retrying from its last checkpoint" in log:
        print("  a trial was retried from its checkpoint instead of going on")
        found["restarted"] += 1
    loaded = load_spec(spec)
    client = mlflow.MlflowClient(loaded.tracking.uri)
    exp = client.get_experiment_by_name(loaded.experiment)
    lost = sum(
        m.value
        for run in client.search_runs([exp.experiment_id])
        for m in client.get_metric_history(run.info.run_id, AGENT_SUBTASKS_LOST)
    )
    print(f"  sub-tasks lost with the runner, as logged: {lost:.0f}")
    return found


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def spec_driver_stacked(directory: Path, iterations: int) -> Path:
    return write_spec(
        directory,
        "drill_driver_stacked",
        iterations,
        search={"tree_depth": {"grid": [1]}},
        seeds=[0, 1, 2],
        seeds_per_trial=3,
    )


def drill_driver_stacked(directory: Path, iterations: int) -> dict[str, int]:
    spec = spec_driver_stacked(directory, iterations)
    fault = {"COPILOT_RAY_FAULT": "planner_nan@3:seed=1"}
    tune_dir = directory / "results" / "drill_driver_stacked" / "tune"
    # (a seed that failed makes the sweep's exit status 1)
    kill_driver_then_resume(spec, tune_dir, at=4, env_extra=fault, exit_codes=(1,))
    logs = "\n".join(p.read_text() for p in sorted(directory.glob("drill_driver_stacked.*.log")))
    stopped = [line for line in logs.splitlines() if "seed 1 stopped" in line]
    print(f"  console: {stopped[-1].strip() if stopped else '(no line for the stopped seed)'}")
    found = audit(spec, iterations, failing_seeds=("1",))
    if not stopped:
        found["lost"] += 1
    return found


def spec_nan(directory: Path, iterations: int) -> Path:
    return write_spec(directory, "drill_nan", iterations, search={"tree_depth": {"grid": [1]}}, seeds=[0, 1])


def drill_nan(directory: Path, iterations: int) -> dict[str, int]:
    spec = spec_nan(directory, iterations)
    proc = sweep(spec, env_extra={"COPILOT_RAY_FAULT": "planner_nan@3:seed=1"})
    code = proc.wait(timeout=900)
    log = max(directory.glob("drill_nan.*.log")).read_text()
    errors = [line for line in log.splitlines() if "ERROR:" in line]
    print(f"  sweep exit status {code}; console: {errors[-1].strip() if errors else '(no ERROR line)'}")
    found = audit(spec, iterations, failing_seeds=("1",))
    if not errors or "non-finite" not in errors[-1]:
        found["lost"] += 1
    return found


# Each drill's spec, written without running it (tests/test_benchmark_specs.py runs them through the
# spec check, so a new rule cannot break a drill unseen).
DRILL_SPECS = {
    "driver": spec_driver,
    "driver_her": spec_driver_her,
    "driver_hrl": spec_driver_hrl,
    "driver_optuna": spec_driver_optuna,
    "driver_stacked": spec_driver_stacked,
    "trial": spec_trial,
    "runner": spec_runner,
    "nan": spec_nan,
}

DRILLS = {
    "driver": drill_driver,
    "driver_her": drill_driver_her,
    "driver_hrl": drill_driver_hrl,
    "driver_optuna": drill_driver_optuna,
    "driver_stacked": drill_driver_stacked,
    "trial": drill_trial,
    "runner": drill_runner,
    "nan": drill_nan,
}


@contextlib.contextmanager
def work_folder(keep: Path | None) -> Iterator[Path]:
    """Where the drills work: --keep's folder, kept (and said so), else a new one in the system's temp
    folder, removed at the end (the drills' results and checkpoints: ~200 MB), with where it was."""
    directory = keep or Path(tempfile.mkdtemp(prefix="copilot_drills_"))
    directory.mkdir(parents=True, exist_ok=True)
    try:
        yield directory
    finally:
        if keep is None:
            shutil.rmtree(directory, ignore_errors=True)
            print(f"removed the drills' work folder {directory} (--keep DIR keeps one)", flush=True)
        else:
            print(f"kept the drills' work folder {directory}", flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drills", nargs="+", default=list(DRILLS), choices=list(DRILLS))
    parser.add_argument("--iterations", type=int, default=6, help="iterations per trial")
    parser.add_argument(
        "--keep",
        type=Path,
        metavar="DIR",
        help="work in this folder and keep it (default: a new folder in the system's temp folder, removed "
        "at the end)",
    )
    parser.add_argument(
        "--kill-seed",
        type=int,
        default=0,
        help="runner drill: seed of the kill's moment within the 3rd iteration",
    )
    args = parser.parse_args()
    global KILL_SEED
    KILL_SEED = args.kill_seed
    bad = 0
    with work_folder(args.keep) as directory:
        for name in args.drills:
            started = time.time()
            print(f"drill {name} (in {directory}):", flush=True)
            found = DRILLS[name](directory, args.iterations)
            print(
                f"drill {name}: runs lost {found['lost']}, duplicated {found['duplicated']}, "
                f"restarted from scratch {found['restarted']} ({time.time() - started:.0f} s)",
                flush=True,
            )
            bad += sum(found.values())
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
