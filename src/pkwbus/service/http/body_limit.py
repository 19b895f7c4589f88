"""A body's size limit for the HTTP API, as ASGI middleware: 413 before the body is read
further, whether it announces its length or comes chunked."""

from __future__ import annotations

from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = ["BodyLimit"]


class _TooLarge(BaseException):
    """Raised out of ``receive``; a BaseException so that FastAPI's body parsing,
    which turns every Exception into 400, lets it through to :class:`BodyLimit`."""


class BodyLimit:
    """ASGI middleware: a body over ``limit`` bytes gets 413, whether it announces its
    length or comes chunked; nothing beyond the limit is kept in memory."""

    def __init__(self, app: ASGIApp, limit: int, large: tuple[str, int] | None = None) -> None:
        self.app = app
        self.limit = limit
        self.large = large  # (the end of a path, its own limit)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if self.large is not None and str(scope.get("path", "")).endswith(self.large[0]):
            await BodyLimit(self.app, self.large[1])(scope, receive, send)
            return
        headers = dict(scope.get("headers") or [])
        length = headers.get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.limit):
            await self._refuse(scope, receive, send)
            return
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    raise _TooLarge
            return message

        started = False

        async def watched(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, watched)
        except _TooLarge:
            if not started:
                await self._refuse(scope, receive, send)

    async def _refuse(self, scope: Scope, receive: Receive, send: Send) -> None:
        body = {"error": {"kind": "too_large", "message": f"body over {self.limit} bytes"}}
        await JSONResponse(body, status_code=413)(scope, receive, send)
