"""The UI server the printed command runs (copilot_ray.mlflow_app): MLflow's own, its page carrying a
script that stores the model-training default and a closed assistant panel where the browser holds no
choice yet; every other answer MLflow's as it is. No Ray, no server: the ASGI app is called directly."""

from __future__ import annotations

import asyncio
import json
import re

from copilot_ray import mlflow_app
from copilot_ray.commands import UI_APP

PAGE = b'<!doctype html><html><head><meta charset="utf-8"/><script src="static-files/main.js"></script></head></html>'


def _inner(body: bytes, content_type: bytes = b"text/html; charset=utf-8", status: int = 200):
    async def app(scope, receive, send):
        headers = [
            (b"content-type", content_type),
            (b"content-length", str(len(body)).encode()),
            (b"etag", b'"1-2-3"'),
            (b"cache-control", b"no-cache"),
        ]
        await send({"type": "http.response.start", "status": status, "headers": headers})
        await send({"type": "http.response.body", "body": body[:10], "more_body": True})
        await send({"type": "http.response.body", "body": body[10:]})

    return app


def _get(app, path: str, method: str = "GET"):
    sent = []

    async def receive():
        return {"type": "http.request", "body": b""}

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "method": method, "path": path, "headers": []}
    asyncio.run(app(scope, receive, send))
    start = sent[0]
    return start["status"], dict(start["headers"]), b"".join(m.get("body", b"") for m in sent[1:])


def test_the_page_stores_model_training_and_a_closed_assistant_before_mlflows_script_runs():
    status, headers, body = _get(mlflow_app.DefaultsApp(_inner(PAGE)), "/")
    assert status == 200 and body.startswith(b"<!doctype html><html><head><script>(function(){")
    assert body.index(b"localStorage") < body.index(b"static-files/main.js")
    assert int(headers[b"content-length"]) == len(body)
    assert b"etag" not in headers and headers[b"cache-control"] == b"no-cache"
    # what it stores, as MLflow's UI stores its own choices (JSON under `<key>_v<version>`)
    pairs = json.loads(re.search(rb"(\[\[.*\]\])\.forEach", body).group(1))
    assert {k: json.loads(v) for k, v in pairs} == {
        "mlflow.workflowType_v1": "machine_learning",
        "mlflow.assistant.fab.autoOpenedOnFirstLoad_v1": True,
    }
    assert b"if(s.getItem(p[0])===null)" in body  # a choice the browser holds stands


def test_every_other_answer_is_mlflows_unchanged():
    for path, method, inner in (
        ("/ajax-api/2.0/mlflow/experiments/get", "GET", _inner(b'{"experiment": {}}', b"application/json")),
        ("/static-files/static/js/main.js", "GET", _inner(b"console.log(1)", b"application/javascript")),
        ("/", "HEAD", _inner(b"")),
        ("/", "GET", _inner(b"not modified", status=304)),
    ):
        status, headers, body = _get(mlflow_app.DefaultsApp(inner), path, method)
        _, expected_headers, expected = _get(inner, path, method)
        assert (headers, body) == (expected_headers, expected)


def test_mlflow_runs_it_as_an_app_not_a_factory():
    """MLflow's `--app-name` starts a function as uvicorn's factory: `app` must be an object."""
    from importlib.metadata import entry_points

    from mlflow.server import _find_app, _is_factory

    (entry,) = [e for e in entry_points(group="mlflow.app") if e.name == UI_APP]
    assert entry.value == "copilot_ray.mlflow_app:app" == _find_app(UI_APP)
    assert not _is_factory(entry.value)
