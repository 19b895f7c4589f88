"""HTTP: /metrics, /healthz, /readyz and the JSON API under /api/v1.

Reading the audit log needs a token: the write token, or the read token named
by ``api.read_token_env``. An error body quotes at most :data:`MAX_MESSAGE`
characters of what it complains about.

The endpoints answer every :class:`~pkwbus.service.writes.checks.ApiError` as a JSON
error body with its status.
"""

from __future__ import annotations

import asyncio
import hmac
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Query, Request, Response, Security
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.security import HTTPBearer
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from pkwbus import __version__
from pkwbus.service.audit.log import AuditError, AuditLog, as_dict
from pkwbus.service.audit.writer import AuditWriter
from pkwbus.service.history.store import HistoryError
from pkwbus.service.http.body_limit import BodyLimit
from pkwbus.service.http.docs_pages import SERVERS, add_docs
from pkwbus.service.http.maintenance import Maintenance
from pkwbus.service.http.models import (
    ERRORS,
    EventsBody,
    Health,
    MaintenanceBody,
    MaintenanceResult,
    Readiness,
    ReloadResult,
    ValueBody,
    WriteBody,
    WriteResult,
)
from pkwbus.service.http.parameters import (
    INCOMPLETE,
    ApiError,
    Caller,
    ParameterService,
    WriteOrder,
)
from pkwbus.service.http.reload import Reloading, Reloads
from pkwbus.service.http.scrape import ScrapePath
from pkwbus.service.http.settings_routes import add_settings_routes
from pkwbus.service.http.view_routes import add_view_routes
from pkwbus.service.http.views import (
    event_views,
    parse_since,
)
from pkwbus.service.metrics import exposition
from pkwbus.service.metrics.instrumentation import api_metrics
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.checks import MAX_DRIVE_NAME, mastered_elsewhere
from pkwbus.service.writes.path import WritePath

__all__ = [
    "BEARER",
    "MAX_AUDIT_LIMIT",
    "MAX_BODY",
    "MAX_MESSAGE",
    "STATIC",
    "Api",
    "BodyLimit",
    "build_api",
    "create_app",
]

MAX_BODY = 4096
MAX_BACKUP_BODY = 1 << 20  # a restore's body: a backup document of many settings
MAX_MESSAGE = 300  # characters of an error message: enough to name the problem
MAX_AUDIT_LIMIT = 1000  # rows of one GET /api/v1/audit
MAX_EVENTS_LIMIT = 1000  # entries of one GET /api/v1/events
# The status page at / and its script and style: package data, nothing from elsewhere.
STATIC = Path(__file__).parent / "static"

# The error kind of Starlette's own answers (a path no route has, a method it does not take).
_HTTP_KINDS = {404: "not_found", 405: "method_not_allowed"}

# Declares the token in the OpenAPI schema (the Authorize button of /docs); the
# endpoints check it themselves, so that every refusal is counted and audited.
BEARER = HTTPBearer(
    auto_error=False,
    scheme_name="token",
    description="the write token (writes, the audit log) or the read token (the audit log)",
)


@dataclass(frozen=True)
class Api:
    """The HTTP app of a runtime and what the service holds of it: the audit log's writer,
    how a reloaded configuration's tokens apply, the reloads (SIGHUP's too), and the one
    write path, for other callers (MQTT) to write through as the API does."""

    app: FastAPI
    audit_writer: AuditWriter
    set_tokens: Callable[[str | None, str | None], None]
    reloads: Reloads | None
    writes: WritePath


def create_app(
    runtime: Runtime,
    *,
    audit: AuditLog | None = None,
    write_token: str | None = None,
    read_token: str | None = None,
    reloader: Reloading | None = None,
) -> FastAPI:
    """The HTTP app of ``runtime`` (:func:`build_api`'s)."""
    return build_api(
        runtime, audit=audit, write_token=write_token, read_token=read_token, reloader=reloader
    ).app


def build_api(
    runtime: Runtime,
    *,
    audit: AuditLog | None = None,
    write_token: str | None = None,
    read_token: str | None = None,
    reloader: Reloading | None = None,
) -> Api:
    """The HTTP app of ``runtime``, handed everything it serves explicitly, and what the
    service holds of it."""
    # /docs and /redoc with Swagger UI and ReDoc served from the package, no CDN, and
    # every URL the pages and the status page use relative: any path prefix works.
    app = FastAPI(
        title="pkwbus",
        version=__version__,
        description="PKW parameter channel bus master: drives, values and parameter jobs",
        docs_url=None,
        redoc_url=None,
        servers=SERVERS,
    )
    add_docs(app)
    audit_writer = AuditWriter(audit, api_metrics(runtime.registry))
    service = ParameterService(runtime, audit_writer, write_token)
    switches = Maintenance(runtime, audit_writer, service.tokens)
    settings = service.settings()
    audit_tokens = [t.encode() for t in (write_token, read_token) if t]

    def set_tokens(write: str | None, read: str | None) -> None:
        """The tokens of a reloaded configuration, from now on."""
        service.tokens.set(write, audit_writer.token_id(write) if write is not None else None)
        audit_tokens[:] = [t.encode() for t in (write, read) if t]

    reloads = Reloads(reloader, audit_writer, service.tokens) if reloader is not None else None

    @app.exception_handler(ApiError)
    async def api_error(request: Request, exc: ApiError) -> JSONResponse:
        return _error_response(exc)

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = [
            f"{'.'.join(_cap(str(x), 40) for x in e.get('loc', ()))}: {e.get('msg', '')}"
            for e in exc.errors()[:5]
        ]
        return await malformed(request, _cap("; ".join(problems)))

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        """Starlette's own answers in the API's shape: a body it cannot read (not UTF-8,
        nested too deep) as any malformed body; an unknown path, a method not allowed."""
        if exc.status_code == 400:
            return await malformed(request, _cap(f"body: {exc.detail}"))
        kind = _HTTP_KINDS.get(exc.status_code, "http_error")
        body = {"error": {"kind": kind, "message": _cap(str(exc.detail))}}
        return JSONResponse(body, status_code=exc.status_code, headers=exc.headers)

    async def malformed(request: Request, message: str) -> JSONResponse:
        """422 invalid_request; a PUT to a drive's parameter or maintenance audited."""
        body: dict[str, Any] = {"error": {"kind": "invalid_request", "message": message}}
        params = request.path_params
        if request.method == "PUT" and "drive" in params:
            caller = Caller(_client(request), request.headers.get("authorization"))
            try:
                if "parameter" in params:
                    stored = await service.refuse_malformed(
                        params["drive"], params["parameter"], caller, message
                    )
                else:  # a drive's maintenance
                    stored = await switches.refuse_malformed(params["drive"], caller, message)
            except ApiError as refused:  # no valid token: that is the answer
                return _error_response(refused)
            if not stored:
                body["audit"] = INCOMPLETE
        return JSONResponse(body, status_code=422)

    async def authorize_audit(request: Request) -> None:
        """The audit log is for holders of the write or the read token."""
        scheme, _, given = (request.headers.get("authorization") or "").partition(" ")
        given = given.strip()
        if not audit_tokens:
            refusal = ApiError(
                403,
                "forbidden",
                "reading the audit log needs a token and none is set"
                " (api.write_token_env, api.read_token_env)",
            )
        elif scheme.lower() != "bearer" or not given:
            refusal = ApiError(
                401, "unauthenticated", "the audit log needs Authorization: Bearer <token>"
            )
        elif not any([hmac.compare_digest(given.encode(), t) for t in audit_tokens]):
            refusal = ApiError(403, "forbidden", "the token is not the write or the read token")
        else:
            return
        refusal.audit_incomplete = not await audit_writer.refused(_client(request), refusal.kind)
        raise refusal

    app.add_middleware(BodyLimit, limit=MAX_BODY, large=("/restore", MAX_BACKUP_BODY))
    app.add_middleware(ScrapePath, registry=runtime.registry)  # GET /metrics, before routing

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
        dependencies=[Security(BEARER)],
    )
    async def write_parameter(
        drive: str, parameter: str, body: WriteBody, request: Request
    ) -> dict[str, Any]:
        order = WriteOrder(body.value, body.index, body.store, body.verify, body.dry_run)
        caller = Caller(_client(request), request.headers.get("authorization"))
        return await service.write(drive, parameter, order, caller)

    @app.put(
        "/api/v1/drives/{drive}/maintenance",
        response_model=MaintenanceResult,
        responses=ERRORS,
        dependencies=[Security(BEARER)],
    )
    async def maintenance(drive: str, body: MaintenanceBody, request: Request) -> dict[str, Any]:
        """``on``: nothing goes out to the drive (not even a probe; a DP slave is left out of
        the cycle) and it is neither up nor down, until ``on`` is false: then it is a drive
        that came back. Audited."""
        caller = Caller(_client(request), request.headers.get("authorization"))
        return await switches.switch(drive, body.on, body.reason, caller)

    add_settings_routes(app, settings, ERRORS, BEARER, _client)

    @app.get("/api/v1/audit", responses=ERRORS, dependencies=[Security(BEARER)])
    async def audit_log(
        request: Request, limit: int = Query(default=100, ge=1, le=MAX_AUDIT_LIMIT)
    ) -> list[dict[str, Any]]:
        await authorize_audit(request)
        if audit is None:
            return []
        try:
            entries = await asyncio.to_thread(audit.latest, limit)
        except AuditError as exc:
            raise ApiError(503, "audit_unavailable", str(exc)) from None
        return [as_dict(e) for e in entries]

    @app.get("/api/v1/events", response_model=EventsBody, responses=ERRORS)
    async def events(
        drive: str | None = Query(default=None, max_length=MAX_DRIVE_NAME),
        since: str | None = Query(default=None, max_length=64),
        limit: int = Query(default=100, ge=1, le=MAX_EVENTS_LIMIT),
    ) -> EventsBody:
        """The drives' own log entries, newest first."""
        if drive is not None and drive not in runtime.drives:
            mastered_elsewhere(runtime, drive)  # its log is read by its line's master
            raise ApiError(404, "unknown_drive", f"no drive is named {drive!r}")
        after = parse_since(since)
        if runtime.history is None:
            return EventsBody(events=[])
        try:
            found = await asyncio.to_thread(
                runtime.history.latest, drive=drive, since=after, limit=limit
            )
        except HistoryError as exc:
            raise ApiError(503, "history_unavailable", str(exc)) from None
        return EventsBody(events=event_views(found))

    @app.get("/healthz", response_model=Health)
    async def healthz() -> Health:
        return Health(status="ok")

    @app.get("/readyz", response_model=Readiness, responses={503: {"model": Readiness}})
    async def readyz() -> Any:
        lines = dict(runtime.snapshot.lines)
        problem = await audit_writer.problem()
        reason = None if problem is None else f"the audit log cannot record: {problem}"
        # In hot standby an instance that masters no line is ready: it stands by.
        some = bool(lines) or runtime.masters is not None
        ready = some and all(lines.values()) and problem is None
        body = Readiness(ready=ready, lines=lines, writes=problem is None, reason=reason)
        if ready:
            return body
        return JSONResponse(body.model_dump(), status_code=503)

    @app.post("/api/v1/reload", response_model=ReloadResult, responses=ERRORS,
              dependencies=[Security(BEARER)])  # fmt: skip
    async def reload(request: Request) -> dict[str, Any]:
        """Read the configuration file again and apply what changed (as SIGHUP does): a
        file with problems changes nothing (422 with the problems). Audited."""
        if reloads is None:
            raise ApiError(409, "reload_unavailable", "this service has no file to reload")
        caller = Caller(_client(request), request.headers.get("authorization"))
        return await reloads.by_api(caller)

    @app.get("/metrics", include_in_schema=False)
    async def metrics() -> Response:
        payload = await exposition.render(runtime.registry)
        return Response(payload, media_type=exposition.CONTENT_TYPE)

    app.mount("/assets/status", StaticFiles(directory=STATIC), name="status-assets")

    @app.get("/", include_in_schema=False)
    async def status_page() -> FileResponse:
        return FileResponse(STATIC / "status.html", media_type="text/html")

    add_view_routes(app, runtime, ERRORS)

    return Api(app, audit_writer, set_tokens, reloads, service.write_path)


def _client(request: Request) -> str:
    return request.client.host if request.client else "unknown"


def _cap(text: str, limit: int = MAX_MESSAGE) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _error_response(exc: ApiError) -> JSONResponse:
    body = exc.body()
    error = body["error"]
    for key, value in error.items():
        if isinstance(value, str):
            error[key] = _cap(value)
    return JSONResponse(body, status_code=exc.status)
