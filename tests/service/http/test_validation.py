"""Writes that are wrong in themselves: 404 or 422, nothing on the bus, one audit row each."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.http.conftest import AUTH, USS_DRIVES, service

CASES: list[tuple[str, str, str, Any, int, str]] = [
    # id, drive, parameter, body (dict, or raw JSON text), status, error kind
    ("string_for_number", "fan1", "3-41", {"value": "ten"}, 422, "invalid_value"),
    ("numeric_string", "fan1", "3-41", {"value": "10"}, 422, "invalid_value"),
    ("boolean", "fan1", "3-41", {"value": True}, 422, "invalid_request"),
    ("null", "fan1", "3-41", {"value": None}, 422, "invalid_request"),
    ("list", "fan1", "3-41", {"value": [1]}, 422, "invalid_request"),
    ("below_catalog_min", "fan1", "3-41", {"value": -1}, 422, "invalid_value"),
    ("u32_range", "fan1", "3-41", {"value": 5e7}, 422, "invalid_value"),
    ("u16_range", "fan1", "4-14", {"value": 6553.6}, 422, "invalid_value"),
    ("resolution", "fan1", "3-41", {"value": 1.234}, 422, "invalid_value"),
    ("resolution_u16", "fan1", "4-14", {"value": 50.05}, 422, "invalid_value"),
    ("nan", "fan1", "3-41", '{"value": NaN}', 422, "invalid_request"),
    ("infinity", "fan1", "3-41", '{"value": Infinity}', 422, "invalid_request"),
    ("huge_int", "fan1", "3-41", {"value": 10**40}, 422, "invalid_value"),
    ("index_256", "fan1", "3-41", {"value": 10, "index": 256}, 422, "invalid_request"),
    ("index_negative", "fan1", "3-41", {"value": 10, "index": -1}, 422, "invalid_request"),
    ("index_conflict", "fan1", "3-41[2]", {"value": 10, "index": 3}, 422, "invalid_index"),
    ("extra_key", "fan1", "3-41", {"value": 10, "force": True}, 422, "invalid_request"),
    ("missing_value", "fan1", "3-41", {}, 422, "invalid_request"),
    ("bad_store", "fan1", "3-41", {"value": 10, "store": "flash"}, 422, "invalid_request"),
    ("not_json", "fan1", "3-41", "value=10", 422, "invalid_request"),
    ("not_utf8", "fan1", "3-41", b'{"value": "\xff\xfe"}', 422, "invalid_request"),
    (
        "nested_too_deep",
        "fan1",
        "3-41",
        '{"value": ' + "[" * 2000 + "]" * 2000 + "}",
        422,
        "invalid_request",
    ),
    ("unknown_drive", "nope", "3-41", {"value": 10}, 404, "unknown_drive"),
    ("notation", "fan1", "banana", {"value": 10}, 404, "unknown_parameter"),
    ("notation_index", "fan1", "3-41[999]", {"value": 10}, 404, "unknown_parameter"),
    ("fc_cannot_encode", "fan1", "5000", {"value": 10}, 404, "unknown_parameter"),
    ("f32_range", "pump1", "p1120", {"value": 1e39}, 422, "invalid_value"),
    ("below_f32_min", "pump1", "p1120", {"value": -1.0}, 422, "invalid_value"),
    ("f32_underflow", "pump1", "p1120", {"value": 1e-50}, 422, "invalid_value"),
    ("f32_subnormal", "pump1", "p1120", {"value": 1e-40}, 422, "invalid_value"),
    ("f32_inexact", "pump1", "p1120", {"value": 16777217}, 422, "invalid_value"),
    ("siemens_on_fc", "fan1", "p0341", {"value": 10}, 422, "wrong_notation"),
]


@pytest.mark.parametrize(
    ("drive", "parameter", "body", "status", "kind"),
    [c[1:] for c in CASES],
    ids=[c[0] for c in CASES],
)
async def test_refused_before_sending(
    tmp_path: Path, drive: str, parameter: str, body: Any, status: int, kind: str
) -> None:
    async with service(tmp_path, uss=USS_DRIVES) as svc:
        url = f"/api/v1/drives/{drive}/parameters/{parameter}"
        if isinstance(body, str | bytes):
            headers = {**AUTH, "Content-Type": "application/json"}
            r = await svc.client.put(url, content=body, headers=headers)
        else:
            r = await svc.client.put(url, json=body, headers=AUTH)
        assert r.status_code == status, r.text
        error = r.json()["error"]
        assert error["kind"] == kind, error
        assert error["message"]
        assert svc.audit_writer.writes() == []
        # nothing but polls reached any drive (no pre-read either)
        polled = {p.request.pnu for d in svc.runtime.drives.values() for p in d.polls}
        assert {1613, 21} <= polled
        assert {req.pnu for _, req in svc.audit_writer.requests} <= polled
        assert svc.audit is not None
        rows = svc.audit.latest(10)
        assert [row.outcome for row in rows] == ["invalid"]
        assert rows[0].drive == drive
        assert rows[0].token_id is not None  # the caller had the right token
        # and the audit stays readable over HTTP
        r = await svc.client.get("/api/v1/audit", headers=AUTH)
        assert r.status_code == 200
        assert len(r.json()) == 1


async def test_a_valid_value_at_the_resolution_goes_through(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        for value, raw in ((0.01, 1), (12.34, 1234), (3600, 360000), ("12.5", None)):
            r = await svc.put("fan1", "3-41", {"value": value})
            if raw is None:
                assert r.status_code == 422  # a string is not a number
                continue
            assert r.status_code == 200, r.text
            assert r.json()["raw"] == raw
            assert svc.sim.drives[1].value(341) == raw


async def test_a_refusal_names_the_nearest_values(tmp_path: Path) -> None:
    async with service(tmp_path, uss=USS_DRIVES) as svc:
        for drive, parameter, value, message in (
            (
                "fan1",
                "3-41",
                1.234,
                "1.234 is not a multiple of 0.01 for 3-41: nearest 1.23 or 1.24",
            ),
            (
                "fan1",
                "3-41",
                12.345,
                "12.345 is not a multiple of 0.01 for 3-41: nearest 12.34 or 12.35",
            ),
            (
                "pump1",
                "p1120",
                1e-50,
                "1e-50 is below the smallest f32 (it would become 0) for p1120: "
                "nearest 0 or 1.1754944e-38",
            ),
        ):
            r = await svc.put(drive, parameter, {"value": value})
            assert r.status_code == 422
            assert r.json()["error"]["message"] == message
        assert svc.audit_writer.writes() == []


async def test_what_no_route_takes_answers_in_the_apis_shape(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        r = await svc.client.get("/api/v1/nothing-here")
        assert r.status_code == 404 and r.json()["error"]["kind"] == "not_found", r.text
        r = await svc.client.delete("/api/v1/drives/fan1/parameters/3-41", headers=AUTH)
        assert r.status_code == 405, r.text
        assert r.json()["error"]["kind"] == "method_not_allowed"
        assert r.headers["allow"]  # what it takes
