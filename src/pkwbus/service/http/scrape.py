"""``GET /metrics`` answered in front of the app's routing: the scrape's text, megabytes at
plant scale, goes out as one body, without the work FastAPI does for a request
(routing, dependencies, the body limit of requests that carry one). Any other
method or path goes on to the app, which answers it as before (a HEAD or a POST
to /metrics: 405)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry
from starlette.types import ASGIApp, Receive, Scope, Send

from pkwbus.service.metrics import exposition

__all__ = ["METRICS_PATH", "ScrapePath"]

METRICS_PATH = "/metrics"
_HEADERS = [(b"content-type", exposition.CONTENT_TYPE.encode("latin-1"))]


class ScrapePath:
    """ASGI middleware: ``GET /metrics`` is the registry's text, straight from
    :func:`~pkwbus.service.metrics.exposition.render`."""

    def __init__(self, app: ASGIApp, registry: CollectorRegistry) -> None:
        self.app = app
        self.registry = registry

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or scope["method"] != "GET"
            or scope["path"] != METRICS_PATH
            or scope.get("root_path")
        ):
            await self.app(scope, receive, send)
            return
        body = await exposition.render(self.registry)
        headers = [(b"content-length", str(len(body)).encode("latin-1")), *_HEADERS]
        await send({"type": "http.response.start", "status": 200, "headers": headers})
        await send({"type": "http.response.body", "body": body})
