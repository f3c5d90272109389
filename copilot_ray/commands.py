"""The commands a program prints for the user to run next name this install's own Python and MLflow, so
that they run as printed from the folder the program ran in, with no virtual environment activated
(a plain `python` or `mlflow` is another install, or none). Standard library only."""

from __future__ import annotations

import os
import shlex
import sys
from pathlib import Path

# MLflow 3's server starts a job runner (huey consumers: seven processes) for its GenAI features, which
# slows its start by tens of seconds; looking at runs needs none of it. One worker process is plenty
# for one person's browser and starts fastest.
UI_ENVIRONMENT = {"MLFLOW_SERVER_ENABLE_JOB_EXECUTION": "false"}
UI_PORT = 5000
# MLflow's `--app-name` of copilot_ray's UI server (copilot_ray.mlflow_app; its entry point: pyproject.toml)
UI_APP = "copilot"


def relative_path(path: str | Path) -> str:
    """`path` relative to the working directory when it is under it (`.venv/bin/python` from a checkout's
    root), else absolute."""
    path = Path(path).absolute()
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def shown_path(path: str | Path) -> str:
    """`relative_path`, quoted for a shell."""
    return shlex.quote(relative_path(path))


def python() -> str:
    """The interpreter running this program, as a command."""
    return shown_path(sys.executable)


def python_module(module: str, *args: object) -> str:
    """`<this python> -m module args...`, each argument quoted for a shell."""
    return " ".join([python(), "-m", module, *(shlex.quote(str(a)) for a in args)])


def mlflow() -> str:
    """This install's `mlflow` script (beside the interpreter, as a virtual environment has it), else
    `<this python> -m mlflow`."""
    script = Path(sys.executable).parent / "mlflow"
    return shown_path(script) if os.access(script, os.X_OK) else f"{python()} -m mlflow"


def ui_app() -> str | None:
    """MLflow's `--app-name` of copilot_ray's UI server (copilot_ray.mlflow_app: model training and no
    assistant panel by default) where this install has its entry point (pyproject.toml), else None (an
    install from before it: MLflow's own server)."""
    from importlib.metadata import entry_points

    return UI_APP if any(e.name == UI_APP for e in entry_points(group="mlflow.app")) else None


def mlflow_ui(tracking_uri: str, port: int = UI_PORT) -> str:
    """The command that serves `tracking_uri`'s runs in MLflow's UI on 127.0.0.1:`port`, quickly, opening
    on the model-training pages (`ui_app`)."""
    env = " ".join(f"{k}={v}" for k, v in UI_ENVIRONMENT.items())
    app = ui_app()
    return " ".join(
        [
            env,
            mlflow(),
            "ui",
            *(["--app-name", app] if app else []),
            f"--workers 1 --port {port} --backend-store-uri {shlex.quote(tracking_uri)}",
        ]
    )
