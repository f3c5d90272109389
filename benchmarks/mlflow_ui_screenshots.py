"""Screenshots of MLflow's UI on a sweep store, taken by headless Chromium: what a user sees first.

Starts MLflow's UI on the given store with the command a sweep prints (`copilot_ray.commands.mlflow_ui`:
this install's mlflow, no job runner, one worker; its own process group, on 127.0.0.1), waits until it
answers, takes the screenshots below with Chromium, stops the server it started (by its PID's process
group) and prints every file it wrote:

  trials_table.png  the link a sweep prints: its trials by configuration, swept values and figures as columns
  trials_chart.png  the chart link it prints beside: success against env steps, one line per configuration
  experiment.png    http://HOST:PORT/#/experiments/<id>?workflowType=machine_learning (no view: MLflow's own)
  run.png           one trial (child) run's page

The view is the experiment's `mlflow.sharedViewState.trials` tag, which the sweep writes
(copilot_ray.mlflow_view); a store from before it has none, and its links fall back to MLflow's default.
A fresh browser (these screenshots: a throwaway profile each) sees what a new user sees.

Usage (on a copy of the store: MLflow may migrate the schema of an older one):

    cp results/demo/mlflow.db /tmp/demo.db
    .venv/bin/python benchmarks/mlflow_ui_screenshots.py /tmp/demo.db docs/mlflow_ui \\
        --experiment demo [--set-note TEXT] [--run RUN_ID] [--port 5055]

Needs Debian's Chromium (`apt-get install -y chromium`; `--chromium PATH` for another binary), run with
the flags of `CHROMIUM_FLAGS` (no sandbox, no GPU, no network beyond the page, a throwaway profile).
Exit status: 0 all written, 1 a screenshot missing, 2 the server did not start.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from copilot_ray import mlflow_view
from copilot_ray.commands import mlflow_ui

NOTE_TAG = "mlflow.note.content"  # the spec's description, which the sweep sets as the experiment's note
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("store", help="SQLite file (or a sqlite:/// URI) of the MLflow store")
    p.add_argument("out", type=Path, help="folder for the PNGs")
    p.add_argument("--experiment", help="experiment name (default: the first one that is not 'Default')")
    p.add_argument("--run", help="the run to show (default: the experiment's first trial run)")
    p.add_argument(
        "--set-note",
        metavar="TEXT",
        help=f"set {NOTE_TAG} (the experiment's description) on the experiment first",
    )
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=5055)
    p.add_argument("--window-size", default="1600,1000")
    p.add_argument(
        "--budget-ms", type=int, default=60000, help="Chromium's --virtual-time-budget (charts need ~40 s)"
    )
    p.add_argument("--chromium", default=shutil.which("chromium") or "chromium")
    return p.parse_args(argv)


def store_uri(store: str) -> str:
    return store if "://" in store else f"sqlite:///{Path(store).resolve()}"


def pick(uri: str, experiment: str | None, run: str | None, note: str | None) -> tuple[str, str]:
    """(experiment id, run id) to show; sets the note when asked."""
    import mlflow

    client = mlflow.MlflowClient(uri)
    if experiment:
        exp = client.get_experiment_by_name(experiment)
        if exp is None:
            raise SystemExit(f"error: no experiment {experiment!r} in {uri}")
    else:
        exps = [e for e in client.search_experiments() if e.name != "Default"]
        if not exps:
            raise SystemExit(f"error: no experiment in {uri}")
        exp = exps[0]
    if note:
        client.set_experiment_tag(exp.experiment_id, NOTE_TAG, note)
    if run is None:
        trials = client.search_runs(
            [exp.experiment_id],
            "tags.`copilot.role` = 'trial'",
            max_results=1,
            order_by=["attributes.start_time ASC"],
        )
        runs = trials or client.search_runs([exp.experiment_id], max_results=1)
        if not runs:
            raise SystemExit(f"error: experiment {exp.name!r} has no runs")
        run = runs[0].info.run_id
    return exp.experiment_id, run


def wait_until_up(url: str, proc: subprocess.Popen, timeout_s: float = 90.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        try:
            with urllib.request.urlopen(url + "/health", timeout=2) as r:
                if r.status == 200:
                    return True
        except OSError:
            pass
        time.sleep(1.0)
    return False


def screenshot(chromium: str, url: str, path: Path, window: str, budget_ms: int) -> bool:
    with tempfile.TemporaryDirectory(prefix="chromium-profile-") as profile:
        cmd = [
            chromium,
            *CHROMIUM_FLAGS,
            f"--user-data-dir={profile}",
            f"--window-size={window}",
            f"--virtual-time-budget={budget_ms}",
            f"--screenshot={path}",
            url,
        ]
        try:
            subprocess.run(cmd, capture_output=True, timeout=120, check=False)
        except subprocess.TimeoutExpired:
            return False
    return path.is_file() and path.stat().st_size > 0


def stop(proc: subprocess.Popen) -> None:
    """Stops the server this script started: its process group (the PID it was started with), so that
    the workers uvicorn forked go too."""
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=20)
    except ProcessLookupError:
        return
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    uri = store_uri(args.store)
    exp_id, run_id = pick(uri, args.experiment, args.run, args.set_note)
    args.out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "MLFLOW_DISABLE_TELEMETRY": "true", "DO_NOT_TRACK": "true"}
    # the command a sweep prints, on this script's host and port
    command = mlflow_ui(uri, args.port).replace(
        f" --port {args.port} ", f" --host {args.host} --port {args.port} "
    )
    log = args.out / "mlflow_ui.log"
    with open(log, "w") as log_file:
        proc = subprocess.Popen(
            ["bash", "-c", f"exec env {command}"],
            env=env,
            stdout=log_file,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    print(f"mlflow ui: PID {proc.pid}, {command}")
    base = f"http://{args.host}:{args.port}"
    written = [log]
    try:
        if not wait_until_up(base, proc):
            print(f"error: mlflow ui did not answer at {base} (see {log})", file=sys.stderr)
            return 2
        ml = "?workflowType=machine_learning"
        pages = {
            "trials_table.png": f"{base}/{mlflow_view.page(exp_id, mlflow_view.TABLE)}",
            "trials_chart.png": f"{base}/{mlflow_view.page(exp_id, mlflow_view.CHART)}",
            "experiment.png": f"{base}/#/experiments/{exp_id}{ml}",
            "run.png": f"{base}/#/experiments/{exp_id}/runs/{run_id}{ml}",
        }
        missing = []
        for name, url in pages.items():
            path = args.out / name
            if screenshot(args.chromium, url, path, args.window_size, args.budget_ms):
                written.append(path)
                print(f"wrote {path}  ({url})")
            else:
                missing.append(name)
                print(f"error: no screenshot of {url}", file=sys.stderr)
    finally:
        stop(proc)
        print(f"stopped mlflow ui (PID {proc.pid})")
    print("files: " + ", ".join(str(p) for p in written))
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
