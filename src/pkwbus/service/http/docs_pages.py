"""/docs (Swagger UI) and /redoc (ReDoc), served from pkwbus itself (no CDN), with URLs
relative to the page: they work under any path prefix a reverse proxy puts before them
(``https://plant/pkwbus/docs`` loads ``https://plant/pkwbus/openapi.json``), with no
setting. The OpenAPI document names its server as ``.``, relative to where it is served
(OpenAPI 3, Server Object), so that "Try it out" reaches the API through the same prefix.
"""

from __future__ import annotations

from pathlib import Path

import fastapi_offline
from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.staticfiles import StaticFiles
from starlette.responses import HTMLResponse

__all__ = ["ASSETS", "SERVERS", "add_docs"]

ASSETS = "assets/docs"  # relative: from /docs and /redoc, ``<prefix>/assets/docs``
SERVERS = [{"url": "."}]
_OFFLINE = Path(fastapi_offline.__file__).parent / "static"


def add_docs(app: FastAPI) -> None:
    """Mount the documentation pages' own assets and add /docs and /redoc."""
    app.mount(f"/{ASSETS}", StaticFiles(directory=_OFFLINE), name="docs-assets")
    openapi = (app.openapi_url or "/openapi.json").lstrip("/")

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi,
            title=f"{app.title} - Swagger UI",
            swagger_js_url=f"{ASSETS}/swagger-ui-bundle.js",
            swagger_css_url=f"{ASSETS}/swagger-ui.css",
            swagger_favicon_url=f"{ASSETS}/favicon.png",
            swagger_ui_parameters=app.swagger_ui_parameters,
        )

    @app.get("/redoc", include_in_schema=False)
    async def redoc() -> HTMLResponse:
        return get_redoc_html(
            openapi_url=openapi,
            title=f"{app.title} - ReDoc",
            redoc_js_url=f"{ASSETS}/redoc.standalone.js",
            redoc_favicon_url=f"{ASSETS}/favicon.png",
            with_google_fonts=False,
        )
