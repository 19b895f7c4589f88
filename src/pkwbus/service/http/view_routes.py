"""The routes of what the API shows of the lines and the drives (:mod:`pkwbus.service.http.views`):
the drives (all, one line's, one drive's, those changed since a token, an overview), their
values' trends, the lines."""

from __future__ import annotations

import time
from typing import Any, Literal

from fastapi import FastAPI, Query, Response

from pkwbus.service.http.models import DriveOverview, DriveView, LineView
from pkwbus.service.http.views import line_views
from pkwbus.service.http.views.drives import TOKEN_HEADER, DriveViews, Selection
from pkwbus.service.http.views.trend_pieces import TrendPieces
from pkwbus.service.runtime import Runtime
from pkwbus.service.writes.checks import MAX_DRIVE_NAME, ApiError, mastered_elsewhere

__all__ = ["add_view_routes"]


def add_view_routes(
    app: FastAPI, runtime: Runtime, errors: dict[int | str, dict[str, Any]]
) -> None:
    """Add the views' routes to ``app``."""
    views = DriveViews(runtime)
    trend_pieces = TrendPieces(runtime)

    @app.get("/api/v1/drives", response_model=list[DriveView] | list[DriveOverview],
             responses=errors)  # fmt: skip
    async def drives(
        line: str | None = Query(default=None, max_length=MAX_DRIVE_NAME),
        drive: str | None = Query(default=None, max_length=MAX_DRIVE_NAME),
        changed_since: str | None = Query(default=None, max_length=64),
        view: Literal["full", "overview"] = "full",
    ) -> Response:
        """The drives with their state and latest values (``view=overview``: one short row
        each); of one ``line`` or one ``drive``; ``changed_since``: only the drives changed
        since the token an earlier answer gave in its X-Changes-Token header (all of them
        when the token is not this run's). Costs what it returns."""
        names, token = views.select(Selection(line, drive, changed_since))
        body = await (views.overview(names) if view == "overview" else views.full(names))
        return Response(body, media_type="application/json", headers={TOKEN_HEADER: token})

    @app.get("/api/v1/trends", response_model=dict[str, dict[str, list[float | None]]],
             responses=errors)  # fmt: skip
    async def trends(
        drive: str | None = Query(default=None, max_length=MAX_DRIVE_NAME),
    ) -> Response:
        """Each drive's values over the last 15 minutes, a point a 15 s (the page's
        sparklines; /metrics and the drives' views keep full precision); ``drive``: of that
        drive alone. Each drive's part is kept until its points change; every drive's
        answer is made a few drives at a time, the loop free in between."""
        now = time.time()
        if drive is None:
            body = await trend_pieces.every(now)
        elif drive not in runtime.drives:
            mastered_elsewhere(runtime, drive)
            raise ApiError(404, "unknown_drive", f"no drive is named {drive!r}")
        else:
            body = trend_pieces.one(drive, now)
        return Response(body, media_type="application/json")

    looks: dict[str, tuple[float, float]] = {}  # line -> (monotonic time, busy seconds)

    @app.get("/api/v1/lines", response_model=list[LineView])
    async def lines() -> list[LineView]:
        return line_views(runtime, looks, time.monotonic())
