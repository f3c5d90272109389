"""MLflow keeps one SQL engine per store URI in this process; a test that deletes a store and puts another
file in its place (a new machine, an unpacked archive) must drop the old engine first. No Ray import."""

from __future__ import annotations


def forget_open_stores(under: str) -> None:
    """Drop this process's engines of the stores whose URI contains ``under``: a new machine opens the
    unpacked file afresh."""
    from mlflow.store.tracking.sqlalchemy_store import SqlAlchemyStore

    for uri in [u for u in SqlAlchemyStore._engine_map if under in u]:
        SqlAlchemyStore._engine_map.pop(uri).dispose()
