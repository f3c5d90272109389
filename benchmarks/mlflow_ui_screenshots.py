"""Screenshots of MLflow's UI on a sweep store, taken by headless Chromium: what a user sees first.

Starts `mlflow ui` on the given store (its own process group, on 127.0.0.1), waits until it answers,
takes the screenshots below with Chromium, stops the server it started (by its PID's process group)
and prints every file it wrote:

  experiment.png     http://HOST:PORT/#/experiments/<id>             what the experiment link opens on
  runs.png           http://HOST:PORT/#/experiments/<id>/runs        the runs page (parents and trials)
  run.png            http://HOST:PORT/#/experiments/<id>/runs/<run>  one trial (child) run
  experiment_ml.png  the experiment link with ?workflowType=machine_learning
  runs_ml.png        the runs page with ?workflowType=machine_learning

Why the last two: MLflow 3.17's UI has a GenAI / Model training switch (`workflowType`: the URL's
`?workflowType=genai|machine_learning`, else the browser's saved choice, else `genai`) that decides the
experiment's pages; with it on (3.17.2: always) the experiment's `mlflow.experimentKind` tag is not what
picks them. A fresh browser (these screenshots: a throwaway profile) sees what a new user sees.

Usage (a copy of the store: `--set-kind` writes the tag the sweep now sets, and MLflow may migrate the
schema of an older store):

    cp results/choose_defaults.db /tmp/cd.db
    .venv/bin/python benchmarks/mlflow_ui_screenshots.py /tmp/cd.db /tmp/mlflow_ui \\
        --experiment choose-defaults --set-kind [--set-note TEXT] [--run RUN_ID] [--port 5055]

Needs Debian's Chromium (`apt-get install -y chromium`; `--chromium PATH` for another binary). The
server runs with MLFLOW_SERVER_ENABLE_JOB_EXECUTION=false (no job runner) and one worker; Chromium with
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

EXPERIMENT_KIND_TAG = "mlflow.experimentKind"  # what copilot_ray.tracking sets on every sweep experiment
EXPERIMENT_KIND = "custom_model_development"
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
        "--set-kind", action="store_true", help=f"set {EXPERIMENT_KIND_TAG} on the experiment first"
    )
    p.add_argument(
        "--set-note",
        metavar="TEXT",
        help=f"set {NOTE_TAG} (the experiment's description) on the experiment first",
    )
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=5055)
    p.add_argument("--window-size", default="1600,1000")
    p.add_argument("--budget-ms", type=int, default=15000, help="Chromium's --virtual-time-budget")
    p.add_argument("--chromium", default=shutil.which("chromium") or "chromium")
    p.add_argument("--mlflow", default=str(Path(sys.executable).with_name("mlflow")))
    return p.parse_args(argv)


def store_uri(store: str) -> str:
    return store if "://" in store else f"sqlite:///{Path(store).resolve()}"


def pick(
    uri: str, experiment: str | None, run: str | None, set_kind: bool, note: str | None
) -> tuple[str, str]:
    """(experiment id, run id) to show; sets the experiment-kind tag and the note when asked."""
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
    if set_kind:
        client.set_experiment_tag(exp.experiment_id, EXPERIMENT_KIND_TAG, EXPERIMENT_KIND)
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
    exp_id, run_id = pick(uri, args.experiment, args.run, args.set_kind, args.set_note)
    args.out.mkdir(parents=True, exist_ok=True)
    env = {
        **os.environ,
        "MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false",
        "MLFLOW_DISABLE_TELEMETRY": "true",
        "DO_NOT_TRACK": "true",
    }
    cmd = [args.mlflow, "ui", "--backend-store-uri", uri, "--host", args.host, "--port", str(args.port)]
    cmd += ["--workers", "1"]
    log = args.out / "mlflow_ui.log"
    with open(log, "w") as log_file:
        proc = subprocess.Popen(
            cmd, env=env, stdout=log_file, stderr=subprocess.STDOUT, start_new_session=True
        )
    print(f"mlflow ui: PID {proc.pid}, {' '.join(cmd)}")
    base = f"http://{args.host}:{args.port}"
    written = [log]
    try:
        if not wait_until_up(base, proc):
            print(f"error: mlflow ui did not answer at {base} (see {log})", file=sys.stderr)
            return 2
        ml = "?workflowType=machine_learning"
        pages = {
            "experiment.png": f"{base}/#/experiments/{exp_id}",
            "runs.png": f"{base}/#/experiments/{exp_id}/runs",
            "run.png": f"{base}/#/experiments/{exp_id}/runs/{run_id}",
            "experiment_ml.png": f"{base}/#/experiments/{exp_id}{ml}",
            "runs_ml.png": f"{base}/#/experiments/{exp_id}/runs{ml}",
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
