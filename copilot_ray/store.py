"""Where MLflow keeps runs: the embedded default store, and which tracking URIs are accepted.

Checked before anything starts (a spec's `tracking.uri`, `--tracking-uri` of `sweep` and `train`), so a
typo is one clear line instead of an MLflow traceback after Ray is up. Standard library only.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from copilot_ray import mlflow_view
from copilot_ray.commands import UI_PORT, mlflow_ui

# MLflow's tracking stores: an embedded SQLite file, a tracking server, or a database it writes to.
SCHEMES = ("sqlite", "http", "https", "postgresql", "mysql", "mssql", "databricks")
ACCEPTED = "sqlite:///<file>, http(s)://<server>[:port] or a database URL (postgresql://, mysql://, mssql://)"


def default_tracking_uri(directory: str | Path = ".") -> str:
    """An embedded SQLite store (MLflow 3 refuses the plain ./mlruns file store by default)."""
    return f"sqlite:///{(Path(directory) / 'mlflow.db').resolve()}"


def tracking_uri_problem(uri: str) -> str | None:
    """Why `uri` cannot be an MLflow tracking store, or None when it can."""
    if not isinstance(uri, str) or not uri.strip():
        return f"must be a tracking URI: {ACCEPTED}"
    scheme, sep, rest = uri.partition("://")
    if not sep:
        return f"has no scheme; use {ACCEPTED}"
    if scheme.split("+")[0] not in SCHEMES:  # postgresql+psycopg2://... is SQLAlchemy's dialect form
        return f"{scheme}:// is not a store MLflow can track to; use {ACCEPTED}"
    if scheme == "sqlite":
        if not rest.startswith("/") or rest == "/":
            return "a SQLite store is sqlite:///<file> (three slashes, then the file's path)"
        path = Path(rest[1:])  # sqlite:///rel/file or sqlite:////abs/file
        if path.is_dir():
            return f"{path} is a folder; name the database file in it (e.g. {path / 'mlflow.db'})"
    elif scheme in ("http", "https") and not rest.split("/")[0]:
        return f"names no server; use {scheme}://<host>[:port]"
    return None


def missing_sqlite_file(uri: str) -> Path | None:
    """The file a sqlite:/// URI names when it does not exist (None for any other store, or when it
    does): reading such a URI would make MLflow create an empty store in its place."""
    if not uri.startswith("sqlite:///"):
        return None
    path = Path(uri[len("sqlite:///") :])
    return None if path.is_file() else path


def unwritable(path: str | Path, kind: str = "folder") -> str | None:
    """Why a `kind` ("folder" or "file") cannot be created or written at `path`, or None when it can.
    Nothing is left behind: the path itself, or else the nearest folder on its way that exists, is
    looked at (a file where a folder must be, no write permission, a folder nothing can be made in)."""
    path = Path(path).expanduser().absolute()
    if path.exists():
        if kind == "folder" and not path.is_dir():
            return f"{path} is a file, not a folder"
        if kind == "file" and path.is_dir():
            return f"{path} is a folder, not a file"
        if not os.access(path, os.W_OK):
            return f"{path} is not writable"
        if path.is_dir() and (why := _cannot_make_in(path)) is not None:
            return f"nothing can be made in {path} ({why})"
        return None
    existing = next(p for p in path.parents if p.exists())
    if not existing.is_dir():
        return f"{existing} is a file, so no {kind} can be made under it"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{existing} is not writable, so {path} cannot be made"
    if (why := _cannot_make_in(existing)) is not None:
        return f"nothing can be made in {existing} ({why}), so {path} cannot be made"
    return None


def _cannot_make_in(folder: Path) -> str | None:
    """Why nothing can be made in the existing `folder` (None when something can), found by making an
    empty folder there and removing it at once: os.access answers yes to root for every folder, /proc's
    and /sys's included, where nothing can be made."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".copilot_ray-write-check-", dir=folder))
    except OSError as err:
        return err.strerror or type(err).__name__
    return None


def unwritable_store(uri: str) -> str | None:
    """Why an embedded SQLite store cannot be written (its file, or its folder to make); None for a
    store that is not a local file."""
    if not uri.startswith("sqlite:///"):
        return None
    return unwritable(uri[len("sqlite:///") :], "file")


def ui_hint(tracking_uri: str, experiment_id: str | None = None, trials_view: bool = False) -> list[str]:
    """How to look at a store's runs in MLflow's UI: the command that serves a local store (this
    install's MLflow, without its job runner) and the pages to open. `trials_view`: a sweep's
    experiment, which carries a view of its trials by configuration (copilot_ray.mlflow_view): its table
    and its chart. `?workflowType=machine_learning` opens an experiment on its runs in MLflow 3's UI
    whatever the browser chose before (the experiment's tags do not decide it; the page the printed
    command serves makes model training the default: copilot_ray.mlflow_app)."""
    if experiment_id is None:
        pages = [""]
    elif trials_view:
        pages = [
            mlflow_view.page(experiment_id, mlflow_view.TABLE),
            mlflow_view.page(experiment_id, mlflow_view.CHART),
        ]
    else:
        pages = [f"#/experiments/{experiment_id}?workflowType=machine_learning"]
    remote = tracking_uri.startswith(("http://", "https://"))
    base = tracking_uri.rstrip("/") if remote else f"http://127.0.0.1:{UI_PORT}"
    lines = [] if remote else [mlflow_ui(tracking_uri)]
    lines.append(f"{'open' if remote else 'then open'} {base}/{pages[0]}")
    lines += [f"success against env steps by configuration: {base}/{p}" for p in pages[1:]]
    return lines
