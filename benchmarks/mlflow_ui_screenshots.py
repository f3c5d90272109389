"""Screenshots of MLflow's UI on a sweep store, taken by headless Chromium as a new user meets it.

Starts MLflow's UI on the store with the command a sweep prints (`copilot_ray.commands.mlflow_ui`: this
install's mlflow, copilot_ray's page (`--app-name copilot`, copilot_ray/mlflow_app.py), no job runner, one
worker; in its own process group, on 127.0.0.1), waits until it answers, drives Chromium over its
DevTools pipe (standard library only: `--remote-debugging-pipe`), stops the server it started (by its
PID's process group; its log: $TMPDIR/mlflow_ui_<port>.log) and prints every file it wrote:

  trials_table.png  the link a sweep prints: its trials by configuration, swept values and figures as columns
  trials_chart.png  the chart link it prints beside: success against env steps, one line per configuration
  experiment.png    the table link, then a click on the experiment's name (the page's breadcrumb)
  run.png           the table link, then a click on the first trial run's name

Each page is a new browser with a new, empty profile: nothing stored, nothing set by this script (what
the page shows it shows a first visit to the server). The view is the experiment's
`mlflow.sharedViewState.trials` tag, which the sweep writes (copilot_ray.mlflow_view); `--view-from
SWEEP.yaml` writes it first as this checkout's code does for the sweep file's parts that write into the
experiment (a store from before the view changed).

Usage (on a copy of the store: MLflow may migrate the schema of an older one, and --view-from writes):

    cp results/pm/results/privilege_matched.db /tmp/pm.db
    .venv/bin/python benchmarks/mlflow_ui_screenshots.py /tmp/pm.db docs/mlflow_ui \\
        --experiment privilege-matched --view-from sweeps/privilege_matched.yaml [--run RUN_ID] [--port 5055]

Needs Debian's Chromium (`apt-get install -y chromium`; `--chromium PATH` for another binary), run with
`CHROMIUM_FLAGS` (no sandbox, no GPU, no network beyond the page, a throwaway profile). The PNGs are
reduced to 256 colours (Pillow, which matplotlib brings) unless `--full-colour`.
Exit status: 0 all written, 1 a screenshot missing, 2 the server did not start.
"""

from __future__ import annotations

import argparse
import base64
import fcntl
import json
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
    p.add_argument("--run", help="the run to click (default: the experiment's first trial run by name)")
    p.add_argument(
        "--view-from",
        type=Path,
        metavar="SWEEP.yaml",
        help="write the experiment's trials view as this checkout makes it for the file's parts first",
    )
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=5055)
    p.add_argument("--window-size", default="1600,1000", help="the page's width,height in CSS pixels")
    p.add_argument("--timeout", type=float, default=120.0, help="seconds a page may take to show its runs")
    p.add_argument("--settle", type=float, default=12.0, help="seconds after that for charts to draw")
    p.add_argument("--full-colour", action="store_true", help="keep the PNGs in full colour")
    p.add_argument("--chromium", default=shutil.which("chromium") or "chromium")
    return p.parse_args(argv)


def store_uri(store: str) -> str:
    return store if "://" in store else f"sqlite:///{Path(store).resolve()}"


def pick(uri: str, experiment: str | None, run: str | None) -> tuple[str, str, str]:
    """(experiment id, experiment name, run name) to show."""
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
    if run is not None:
        return exp.experiment_id, exp.name, client.get_run(run).info.run_name
    runs = client.search_runs(
        [exp.experiment_id],
        "tags.`copilot.role` = 'trial'",
        max_results=1,
        order_by=["tags.`mlflow.runName` ASC"],  # the view's order: the table's first trial
    ) or client.search_runs([exp.experiment_id], max_results=1)
    if not runs:
        raise SystemExit(f"error: experiment {exp.name!r} has no runs")
    return exp.experiment_id, exp.name, runs[0].info.run_name


def write_view(uri: str, experiment_id: str, experiment: str, sweep_file: Path) -> int:
    """The experiment's trials view as this checkout writes it for `sweep_file`'s parts in `experiment`
    (copilot_ray.sweep.trials_view_of, part after part); returns how many parts."""
    import mlflow

    from copilot_ray.sweep import trials_view_of
    from copilot_ray.sweep_spec import load_specs

    parts = [s for s in load_specs(sweep_file) if s.experiment == experiment]
    if not parts:
        raise SystemExit(f"error: no part of {sweep_file} writes into experiment {experiment!r}")
    view = None
    for part in parts:
        view = mlflow_view.trials_view(*trials_view_of(part), earlier=view)
    mlflow.MlflowClient(uri).set_experiment_tag(experiment_id, mlflow_view.VIEW_TAG, mlflow_view.encode(view))
    return len(parts)


class Browser:
    """Headless Chromium on its DevTools pipe (fd 3: its commands in, fd 4: its answers out, each a JSON
    message ended by NUL), one page, a new empty profile; `close` ends it (its process group)."""

    def __init__(self, chromium: str, width: int, height: int):
        self._profile = tempfile.TemporaryDirectory(prefix="chromium-profile-")
        commands_in, self._commands = os.pipe()
        self._answers, answers_out = os.pipe()
        # the child's ends above 4, so that putting them on 3 and 4 never closes one of them
        commands_in, answers_out = (self._above_4(fd) for fd in (commands_in, answers_out))
        # the shell puts the two ends on fds 3 and 4, where Chromium looks for them
        self.proc = subprocess.Popen(
            [
                "sh",
                "-c",
                f'exec "$0" "$@" 3<&{commands_in} 4>&{answers_out} {commands_in}<&- {answers_out}>&-',
                chromium,
                *CHROMIUM_FLAGS,
                f"--user-data-dir={self._profile.name}",
                f"--window-size={width},{height}",
                "--remote-debugging-pipe",
                "about:blank",
            ],
            pass_fds=(commands_in, answers_out),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        os.close(commands_in)
        os.close(answers_out)
        self._buffer, self._id = b"", 0
        page = next(t for t in self.call("Target.getTargets")["targetInfos"] if t["type"] == "page")
        self._session = self.call("Target.attachToTarget", targetId=page["targetId"], flatten=True)[
            "sessionId"
        ]
        self.call(
            "Emulation.setDeviceMetricsOverride",
            page=True,
            width=width,
            height=height,
            deviceScaleFactor=1,
            mobile=False,
        )

    @staticmethod
    def _above_4(fd: int) -> int:
        moved = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 5)
        os.close(fd)
        return moved

    def _message(self) -> dict:
        while b"\0" not in self._buffer:
            chunk = os.read(self._answers, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed its DevTools pipe")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def call(self, method: str, page: bool = False, **params) -> dict:
        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if page:
            message["sessionId"] = self._session
        os.write(self._commands, json.dumps(message).encode() + b"\0")
        while True:  # (events in between are not needed)
            answer = self._message()
            if answer.get("id") == self._id:
                if "error" in answer:
                    raise RuntimeError(f"{method}: {answer['error']}")
                return answer.get("result", {})

    def js(self, expression: str):
        answer = self.call("Runtime.evaluate", page=True, expression=expression, returnByValue=True)
        return None if "exceptionDetails" in answer else answer["result"].get("value")

    def wait_for(self, expression: str, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.js(expression):
                return True
            time.sleep(0.5)
        return False

    def open(self, url: str) -> None:
        self.call("Page.navigate", page=True, url=url)

    def click_link(self, text: str, href_prefix: str) -> str | None:
        """Clicks the first link whose text is `text` and whose address starts with `href_prefix`;
        returns that address (None: no such link)."""
        return self.js(
            "(() => { const a = [...document.querySelectorAll('a')].find(a => a.innerText.trim() === "
            f"{json.dumps(text)} && (a.getAttribute('href') || '').startsWith({json.dumps(href_prefix)})); "
            "if (!a) return null; a.click(); return a.getAttribute('href'); })()"
        )

    def screenshot(self, path: Path) -> None:
        path.write_bytes(
            base64.b64decode(self.call("Page.captureScreenshot", page=True, format="png")["data"])
        )

    def close(self) -> None:
        try:
            self.call("Browser.close")
            self.proc.wait(timeout=20)
        except (RuntimeError, OSError, subprocess.TimeoutExpired):
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait(timeout=10)
        finally:
            os.close(self._commands)
            os.close(self._answers)
            self._profile.cleanup()


def shows(text: str) -> str:
    """A page-side test: the page's text holds `text`."""
    return f"(document.body ? document.body.innerText : '').includes({json.dumps(text)})"


def take(args, name: str, url: str, ready: str, click: tuple[str, str, str] | None = None) -> str | None:
    """One screenshot in a new browser: `url` once `ready` (a page-side test) holds, then (`click`: link
    text, its address's start, a test of the page it opens) a click; returns the address it shows, or
    None when a page did not come."""
    width, height = (int(v) for v in args.window_size.split(","))
    browser = Browser(args.chromium, width, height)
    try:
        browser.open(url)
        if not browser.wait_for(ready, args.timeout):
            return None
        if click is not None:
            time.sleep(2)
            text, href, then = click
            if browser.click_link(text, href) is None or not browser.wait_for(then, args.timeout):
                return None
        time.sleep(args.settle)
        path = args.out / name
        browser.screenshot(path)
        return browser.js("location.href")
    finally:
        browser.close()


def reduce_colours(path: Path) -> None:
    """The PNG in 256 colours (octree: a screenshot's text, lines and colour dots survive it; a third of
    the size)."""
    from PIL import Image

    with Image.open(path) as image:
        reduced = image.convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    reduced.save(path, optimize=True)


def wait_until_up(url: str, proc: subprocess.Popen, timeout_s: float = 120.0) -> bool:
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
    exp_id, experiment, run_name = pick(uri, args.experiment, args.run)
    if args.view_from is not None:
        parts = write_view(uri, exp_id, experiment, args.view_from)
        print(f"wrote the trials view of {parts} part(s) of {args.view_from} into {experiment!r}")
    args.out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "MLFLOW_DISABLE_TELEMETRY": "true", "DO_NOT_TRACK": "true"}
    # the command a sweep prints, on this script's host and port
    command = mlflow_ui(uri, args.port).replace(
        f" --port {args.port} ", f" --host {args.host} --port {args.port} "
    )
    log = Path(tempfile.gettempdir()) / f"mlflow_ui_{args.port}.log"  # (not beside the PNGs)
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
    written, missing = [], []
    try:
        if not wait_until_up(base, proc):
            print(f"error: mlflow ui did not answer at {base} (see {log})", file=sys.stderr)
            return 2
        table = f"{base}/{mlflow_view.page(exp_id, mlflow_view.TABLE)}"
        chart = f"{base}/{mlflow_view.page(exp_id, mlflow_view.CHART)}"
        runs_shown = shows(run_name)
        charts_drawn = "document.querySelectorAll('.js-plotly-plot').length > 0"
        pages = {
            "trials_table.png": (table, runs_shown, None),
            "trials_chart.png": (chart, f"{runs_shown} && {charts_drawn}", None),
            # the experiment's name in the breadcrumb above the table, and the first trial's
            "experiment.png": (
                table,
                runs_shown,
                (
                    experiment,
                    f"#/experiments/{exp_id}",
                    f"!location.hash.includes('viewStateShareKey') && {shows('Run Name')}",
                ),
            ),
            "run.png": (
                table,
                runs_shown,
                (run_name, f"#/experiments/{exp_id}/runs/", shows("About this run")),
            ),
        }
        for name, (url, ready, click) in pages.items():
            shown = take(args, name, url, ready, click)
            path = args.out / name
            if shown is None or not path.is_file():
                missing.append(name)
                print(f"error: no screenshot of {url}{' then a click' if click else ''}", file=sys.stderr)
                continue
            if not args.full_colour:
                reduce_colours(path)
            written.append(path)
            how = f"{url}, then a click on {click[0]!r}" if click else url
            print(f"wrote {path} ({path.stat().st_size // 1024} KiB): {how}; shows {shown}")
    finally:
        stop(proc)
        print(f"stopped mlflow ui (PID {proc.pid})")
    print("files: " + ", ".join(str(p) for p in written))
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
