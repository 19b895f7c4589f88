"""/docs and /redoc work without internet: Swagger UI and ReDoc come from pkwbus itself,
and the OpenAPI schema declares the bearer token so that the Authorize button works."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.service.http.conftest import AUTH, service

# Any absolute URL in src/href, url(...) or a script's import: what a browser would fetch.
FETCHED = re.compile(r"""(?:src|href)\s*=\s*["']([^"']+)["']|url\(\s*["']?([^"')]+)""", re.I)


def fetched(html: str) -> list[str]:
    return [a or b for a, b in FETCHED.findall(html)]


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
async def test_docs_pages_fetch_nothing_from_elsewhere(page: str, tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        r = await svc.client.get(page)
        assert r.status_code == 200
        html = r.text
        assert "cdn." not in html and "fonts.googleapis" not in html
        urls = fetched(html) + re.findall(r"""url:\s*['"]([^'"]+)""", html)
        assert urls, html  # the page does load its assets ...
        for url in urls:  # ... each from this server
            assert not re.match(r"^(?:[a-z]+:)?//", url, re.I), url
            asset = await svc.client.get(url)
            assert asset.status_code == 200, url
            assert asset.content, url


async def test_openapi_declares_the_bearer_token(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        schema = (await svc.client.get("/openapi.json")).json()
        (name, scheme), *more = schema["components"]["securitySchemes"].items()
        assert not more
        assert scheme["type"] == "http" and scheme["scheme"].lower() == "bearer"
        paths = schema["paths"]
        put = paths["/api/v1/drives/{drive}/parameters/{parameter}"]["put"]
        assert put["security"] == [{name: []}]
        assert paths["/api/v1/audit"]["get"]["security"] == [{name: []}]
        for free in ("/api/v1/drives", "/healthz", "/readyz"):
            assert "security" not in paths[free]["get"], free
        # the token is not also a plain header parameter (Swagger UI would ask twice)
        assert all(p["in"] != "header" for p in put.get("parameters", []))


async def test_a_write_still_needs_the_token(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        assert (await svc.put("fan1", "3-41", {"value": 1.5}, headers={})).status_code == 401
        assert (await svc.put("fan1", "3-41", {"value": 1.5}, headers=AUTH)).status_code == 200
