"""The routes of the drives' settings (:mod:`pkwbus.service.http.settings`): the last
sweep, the baseline accepted, a backup document, a restore."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

import yaml
from fastapi import FastAPI, Query, Request, Response, Security
from fastapi.security import HTTPBearer

from pkwbus.service.http.models import RestoreBody
from pkwbus.service.http.settings import DriveSettings
from pkwbus.service.writes.checks import Caller

__all__ = ["add_settings_routes"]


def add_settings_routes(
    app: FastAPI,
    settings: DriveSettings,
    errors: dict[int | str, dict[str, Any]],
    bearer: HTTPBearer,
    client: Callable[[Request], str],
) -> None:
    """Add the settings' routes to ``app``; ``client`` names a request's client."""

    @app.get("/api/v1/drives/{drive}/settings", responses=errors)
    async def drive_settings(drive: str) -> dict[str, Any]:
        """The last sweep of the drive's settings: each with its value, its baseline,
        whether (and since when) it differs from it, and what the drive says of its
        factory setting (null where it says nothing)."""
        return settings.view(drive)

    @app.put(
        "/api/v1/drives/{drive}/settings/baseline",
        responses=errors,
        dependencies=[Security(bearer)],
    )
    async def accept_baseline(drive: str, request: Request) -> dict[str, Any]:
        """The values last read become the drive's baseline (audited)."""
        caller = Caller(client(request), request.headers.get("authorization"))
        return await settings.accept(drive, caller)

    @app.get("/api/v1/drives/{drive}/backup", responses=errors)
    async def backup(
        drive: str,
        format: Literal["json", "yaml"] = Query(default="json"),
        of: Literal["values", "baseline"] = Query(default="values"),
    ) -> Any:
        """The drive's settings last read (or its baseline) as a document: JSON, or YAML."""
        document = await settings.backup(drive, of)
        if format == "yaml":
            text = yaml.safe_dump(document, sort_keys=False, allow_unicode=True)
            return Response(text, media_type="application/yaml")
        return document

    @app.post(
        "/api/v1/drives/{drive}/restore",
        responses=errors,
        dependencies=[Security(bearer)],
    )
    async def restore(drive: str, body: RestoreBody, request: Request) -> dict[str, Any]:
        """Plan the writes that make the drive hold the backup's values; without
        ``dry_run`` write them through the one write path (audited, read back)."""
        caller = Caller(client(request), request.headers.get("authorization"))
        return await settings.restore(
            drive, body.backup, body.dry_run, body.store, body.force, caller
        )
