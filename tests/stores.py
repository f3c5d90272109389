"""MLflow's SQLite stores in the test session. No Ray import, and no MLflow import until a test makes one.

MLflow keeps one SQL engine per store URI in this process; a test that deletes a store and puts another
file in its place (a new machine, an unpacked archive) must drop the old engine first.

A new SQLite store costs MLflow its whole chain of schema migrations (2.5-4 s on two idle cores, twice
that beside an experiment) and the suite opens about 40 of them. The session migrates one empty store,
the first time a test needs one, and each new store after it is a copy of that file, made where MLflow
would have migrated (same MLflow, same schema: MLflow then checks the copy's schema version as usual)."""

from __future__ import annotations

import importlib.abc
import importlib.util
import os
import sys

TEMPLATE_ENV = "COPILOT_RAY_TEST_MLFLOW_TEMPLATE"  # path of the session's migrated empty store
_UTILS = "mlflow.store.db.utils"
_MLFLOW = {}  # MLflow's own migration and engine factory, kept when the first is replaced


def forget_open_stores(under: str) -> None:
    """Drop this process's engines of the stores whose URI contains ``under``: a new machine opens the
    unpacked file afresh."""
    from mlflow.store.tracking.sqlalchemy_store import SqlAlchemyStore

    for uri in [u for u in SqlAlchemyStore._engine_map if under in u]:
        SqlAlchemyStore._engine_map.pop(uri).dispose()


def _migrated_template(migrate, create_engine) -> str:
    """The session's migrated empty store, made by MLflow's own migrations on first use."""
    import fcntl

    path = os.environ[TEMPLATE_ENV]
    if not os.path.exists(path):
        with open(path + ".lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not os.path.exists(path):
                tmp = f"{path}.{os.getpid()}.tmp"
                engine = create_engine(f"sqlite:///{tmp}")
                try:
                    migrate(engine)
                finally:
                    engine.dispose()
                os.replace(tmp, path)
    return path


def _copy_migrated_template(utils) -> None:
    """Replaces ``utils._initialize_tables`` (MLflow creating and migrating the tables of a store that
    has none): an empty SQLite file gets the session's migrated store copied in instead (SQLite's backup,
    through the engine's own connection); any other database is migrated by MLflow as before."""
    import sqlite3

    import sqlalchemy

    migrate = _MLFLOW["migrate"] = utils._initialize_tables
    _MLFLOW["create_engine"] = utils.create_sqlalchemy_engine

    def initialize_tables(engine):
        database = engine.url.database
        if (
            engine.url.get_backend_name() != "sqlite"
            or not database
            or database == ":memory:"
            or sqlalchemy.inspect(engine).get_table_names()  # a half-made store: MLflow's own path
        ):
            return migrate(engine)
        utils._logger.info("Creating initial MLflow database tables...")  # as MLflow says (console.py)
        template = sqlite3.connect(_migrated_template(migrate, utils.create_sqlalchemy_engine))
        connection = engine.raw_connection()
        try:
            template.backup(connection.driver_connection)
        finally:
            connection.close()
            template.close()
        utils._logger.info("Updating database tables")

    utils._initialize_tables = initialize_tables


def migrated_store() -> str:
    """The session's migrated empty store (a file to copy where a process that is not the test's, an
    MLflow server, would otherwise migrate a new store of its own)."""
    import mlflow.store.db.utils  # noqa: F401  (patched as it is imported)

    return _migrated_template(_MLFLOW["migrate"], _MLFLOW["create_engine"])


class _OnImport(importlib.abc.MetaPathFinder):
    """Patches mlflow.store.db.utils as it is imported (MLflow is not imported before a test needs it)."""

    def find_spec(self, name, path, target=None):
        if name != _UTILS:
            return None
        sys.meta_path.remove(self)
        try:
            spec = importlib.util.find_spec(name)
        finally:
            sys.meta_path.insert(0, self)
        if spec is None or spec.loader is None:
            return spec
        load = spec.loader.exec_module

        def exec_module(module):
            load(module)
            _copy_migrated_template(module)

        spec.loader.exec_module = exec_module
        return spec


def copy_a_migrated_store_into_new_stores(directory: str) -> None:
    """From now on in this process a new SQLite store is a copy of one migrated store kept in
    ``directory`` (made on first use)."""
    os.environ[TEMPLATE_ENV] = os.path.join(directory, "migrated-mlflow.db")
    if _UTILS in sys.modules:
        _copy_migrated_template(sys.modules[_UTILS])
    elif not any(isinstance(f, _OnImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _OnImport())
