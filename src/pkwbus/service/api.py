"""HTTP: /metrics, /healthz, /readyz and the JSON API under /api/v1."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import FastAPI, Header, Query, Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt, StrictStr
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from pkwbus import __version__
from pkwbus.protocol import pkw
from pkwbus.protocol.pzd import status_bits
from pkwbus.service.audit import AuditLog, as_dict
from pkwbus.service.parameters import ApiError, Caller, ParameterService, WriteOrder
from pkwbus.service.runtime import Runtime

MAX_BODY = 4096


class ParameterReading(BaseModel):
    parameter: str
    index: int
    value: float | int | str
    raw: int | None
    unit: str
    timestamp: float


class DriveView(BaseModel):
    name: str
    line: str
    protocol: str
    address: int
    dialect: str
    up: bool
    status_word: int | None
    status: dict[str, bool]
    values: list[ParameterReading]


class Health(BaseModel):
    status: str
    version: str = __version__


class Readiness(BaseModel):
    ready: bool
    lines: dict[str, bool]


class WriteBody(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    # Strict: true/false is not 1/0, and "10" stays a string (refused for a number).
    value: StrictInt | StrictFloat | StrictStr = Field(
        description="engineering value, scaled by the catalog; a string for text parameters"
    )
    index: int | None = Field(default=None, ge=0, le=255)
    store: pkw.Store = pkw.Store.RAM
    verify: bool = Field(default=False, description="read the parameter back after writing")
    dry_run: bool = Field(default=False, description="validate and show the telegram only")


class ValueBody(BaseModel):
    parameter: str
    pnu: int
    index: int
    raw: int | None
    value: float | int | str | None
    unit: str


class WriteResult(ValueBody):
    store: str
    dry_run: bool
    telegram: str
    audit_id: int | None
    old_value: float | int | str | None = None
    verified: bool | None = None


class ErrorBody(BaseModel):
    error: dict[str, object]


ERRORS: dict[int | str, dict[str, object]] = {
    code: {"model": ErrorBody} for code in (401, 403, 404, 409, 413, 422, 503, 504)
}


class _TooLarge(BaseException):
    """Raised out of ``receive``; a BaseException so that FastAPI's body parsing,
    which turns every Exception into 400, lets it through to :class:`BodyLimit`."""


class BodyLimit:
    """ASGI middleware: a body over ``limit`` bytes gets 413, whether it announces its
    length or comes chunked; nothing beyond the limit is kept in memory."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
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


def create_app(
    runtime: Runtime, *, audit: AuditLog | None = None, write_token: str | None = None
) -> FastAPI:
    app = FastAPI(
        title="pkwbus",
        version=__version__,
        description="PKW parameter channel bus master: drives, values and parameter jobs",
    )
    app.state.runtime = runtime
    service = ParameterService(runtime, audit, write_token)

    @app.exception_handler(ApiError)
    async def api_error(request: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(exc.body(), status_code=exc.status)

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = [
            f"{'.'.join(str(x) for x in e.get('loc', ()))}: {e.get('msg', '')}"
            for e in exc.errors()
        ]
        message = "; ".join(problems)
        params = request.path_params
        if request.method == "PUT" and "drive" in params and "parameter" in params:
            caller = Caller(_client(request), request.headers.get("authorization"))
            service.refuse_malformed(params["drive"], params["parameter"], caller, message)
        body = {"error": {"kind": "invalid_request", "message": message}}
        return JSONResponse(body, status_code=422)

    app.add_middleware(BodyLimit, limit=MAX_BODY)

    @app.get(
        "/api/v1/drives/{drive}/parameters/{parameter}",
        response_model=ValueBody,
        responses=ERRORS,
    )
    async def read_parameter(
        drive: str, parameter: str, index: int | None = Query(default=None, ge=0, le=255)
    ) -> dict[str, Any]:
        return await service.read(drive, parameter, index)

    @app.put(
        "/api/v1/drives/{drive}/parameters/{parameter}",
        response_model=WriteResult,
        responses=ERRORS,
    )
    async def write_parameter(
        drive: str,
        parameter: str,
        body: WriteBody,
        request: Request,
        authorization: str | None = Header(default=None),
    ) -> dict[str, Any]:
        order = WriteOrder(body.value, body.index, body.store, body.verify, body.dry_run)
        caller = Caller(_client(request), authorization)
        return await service.write(drive, parameter, order, caller)

    @app.get("/api/v1/audit")
    async def audit_log(limit: int = Query(default=100, ge=1, le=10000)) -> list[dict[str, Any]]:
        if audit is None:
            return []
        return [as_dict(e) for e in audit.latest(limit)]

    @app.get("/healthz", response_model=Health)
    async def healthz() -> Health:
        return Health(status="ok")

    @app.get("/readyz", response_model=Readiness, responses={503: {"model": Readiness}})
    async def readyz() -> Any:
        lines = dict(runtime.snapshot.lines)
        ready = bool(lines) and all(lines.values())
        body = Readiness(ready=ready, lines=lines)
        if ready:
            return body
        return JSONResponse(body.model_dump(), status_code=503)

    @app.get("/metrics", include_in_schema=False)
    async def metrics() -> Response:
        payload = await asyncio.to_thread(generate_latest, runtime.registry)
        return Response(payload, media_type=CONTENT_TYPE_LATEST)

    @app.get("/api/v1/drives", response_model=list[DriveView])
    async def drives() -> list[DriveView]:
        return [drive_view(runtime, name) for name in runtime.drives]

    return app


def _client(request: Request) -> str:
    return request.client.host if request.client else "unknown"


def drive_view(runtime: Runtime, name: str) -> DriveView:
    entry = runtime.drives[name]
    snap = runtime.snapshot
    state = snap.drives.get(name)
    word = state.status_word if state else None
    values = [
        ParameterReading(
            parameter=parameter,
            index=index,
            value=reading.value,
            raw=reading.raw,
            unit=entry.unit_of(parameter),
            timestamp=reading.timestamp,
        )
        for (drive, parameter, index), reading in list(snap.readings.items())
        if drive == name
    ]
    return DriveView(
        name=name,
        line=entry.line,
        protocol=entry.target.protocol.value,
        address=entry.target.address,
        dialect=entry.target.dialect.name,
        up=state.up if state else True,
        status_word=word,
        status=status_bits(word, entry.target.profile) if word is not None else {},
        values=values,
    )
