"""MLflow's UI as the commands copilot_ray prints serve it: MLflow's own server, whose page sets two of its
UI's defaults a browser has not chosen yet, so that every way into an experiment (its name, a run, the
experiments list) opens the model-training pages and the assistant panel waits to be asked for.

Why the page and not the store: MLflow 3.17's UI picks its GenAI or model-training pages from the
address's `workflowType`, else from the browser's stored choice (localStorage `mlflow.workflowType_v1`,
which its sidebar's "GenAI | Model training" switch writes), else GenAI; it reads the experiment's
`mlflow.experimentKind` tag only with its workflow switch off, and every build has it on. (MLflow
3.17.2's bundle mlflow/server/js/build/static/js/main.c2f5f8d4.js: module 31080's experiment-kind hook
`l = e => { workflowType = useWorkflowType(); n = Z0(); return n ? m(workflowType) : <the tag> }`,
module 89511's `Z0 = () => !0`, and module 7975's `useWorkflowType`: the address's `workflowType`, else
`useLocalStorage({key: "mlflow.workflowType", version: 1, initialValue: "genai"})`.) The links inside
the UI drop the address's `workflowType`, so a new browser follows them onto GenAI's overview, its
"Detect Issues" prompt and "Evaluations". And on a first visit to a local
server (127.0.0.1, localhost) the UI opens its assistant panel, a quarter of the page, unless
`mlflow.assistant.fab.autoOpenedOnFirstLoad_v1` says it did so before. Neither has a server setting.

So the page MLflow serves at `/` gets one inline script, before MLflow's own, that stores
`DEFAULTS` where the browser holds no value yet: a choice a user made (GenAI, an open panel) stands.
Everything else is MLflow's server as is (`mlflow.server.fastapi_app:app`, imported on first request).

`mlflow ui --app-name copilot` runs it: `copilot` is this module's `app` in the entry-point group
`mlflow.app` (pyproject.toml), which MLflow's `--app-name` chooses from; `copilot_ray.commands.mlflow_ui`
adds the flag where this install has the entry point. `app` is an object, not a function: MLflow starts
a function as uvicorn's factory. Standard library only (MLflow's server at the first request).
"""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable, Mapping
from typing import Any

from copilot_ray.commands import UI_APP  # noqa: F401 - MLflow's `--app-name` of `app` (pyproject.toml)

WORKFLOW_TYPE_KEY = "mlflow.workflowType_v1"
ASSISTANT_AUTO_OPENED_KEY = "mlflow.assistant.fab.autoOpenedOnFirstLoad_v1"
# localStorage values as MLflow's UI stores them (JSON)
DEFAULTS: Mapping[str, Any] = {WORKFLOW_TYPE_KEY: "machine_learning", ASSISTANT_AUTO_OPENED_KEY: True}
PAGE_PATHS = ("/",)  # where MLflow serves its page (the UI's own routes follow `#`)

Scope = Mapping[str, Any]
Message = dict[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]


def defaults_script(defaults: Mapping[str, Any] = DEFAULTS) -> str:
    """The inline script: each key of `defaults` stored (as JSON) unless the browser holds one already."""
    pairs = json.dumps([[k, json.dumps(v)] for k, v in defaults.items()])
    return (
        "<script>(function(){try{var s=window.localStorage;"
        f"{pairs}.forEach(function(p){{if(s.getItem(p[0])===null)s.setItem(p[0],p[1]);}});"
        "}catch(e){}})();</script>"
    )


def with_defaults(page: bytes, script: str | None = None) -> bytes:
    """MLflow's page with the script first in its <head> (unchanged if it has no <head>)."""
    marker = b"<head>"
    at = page.find(marker)
    if at < 0:
        return page
    at += len(marker)
    return page[:at] + (script or defaults_script()).encode() + page[at:]


class DefaultsApp:
    """An ASGI app: `inner` (MLflow's server), its page at PAGE_PATHS given `with_defaults`. The page's
    validators go (ETag, Last-Modified, ranges): a browser's copy of MLflow's plain page is not it."""

    def __init__(self, inner: Callable[..., Awaitable[None]] | None = None):
        self._inner = inner

    @property
    def inner(self):
        if self._inner is None:
            from mlflow.server.fastapi_app import app as mlflow_app

            self._inner = mlflow_app
        return self._inner

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        page = scope["type"] == "http" and scope.get("method") == "GET" and scope.get("path") in PAGE_PATHS
        if not page:
            await self.inner(scope, receive, send)
            return
        start: Message | None = None
        body: list[bytes] = []

        async def collect(message: Message) -> None:
            nonlocal start
            if message["type"] == "http.response.start":
                start = message
                return
            if message["type"] != "http.response.body":
                await send(message)
                return
            body.append(message.get("body", b""))
            if message.get("more_body"):
                return
            await send_page(start, b"".join(body))

        async def send_page(start: Message | None, content: bytes) -> None:
            headers = list((start or {}).get("headers", []))
            html = any(k.lower() == b"content-type" and b"text/html" in v.lower() for k, v in headers)
            if start is not None and start.get("status") == 200 and html:
                content = with_defaults(content)
                dropped = {b"content-length", b"etag", b"last-modified", b"accept-ranges"}
                headers = [(k, v) for k, v in headers if k.lower() not in dropped]
                headers.append((b"content-length", str(len(content)).encode()))
                start = {**start, "headers": headers}
            await send(start)
            await send({"type": "http.response.body", "body": content})

        await self.inner(scope, receive, collect)


app = DefaultsApp()
