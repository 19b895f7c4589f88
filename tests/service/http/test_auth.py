"""Who may write: (no token configured | no header | wrong token | right token) x (writable or not).

Every refused write must leave the drive untouched: no request for the
parameter reached it and its value
is unchanged. Polls run meanwhile, so the check is per parameter.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.service.http.conftest import TOKEN, service

WRITABLE = ("3-41", 341, 12.5, 1250)  # catalog u32, conversion -2 (0.01 s)
NOT_WRITABLE = ("3-03", 303, 10, 10000)  # settable in the catalog, not in `writable`

HEADERS = {
    "none": {},
    "wrong": {"Authorization": "Bearer not-the-token"},
    "prefix": {"Authorization": f"Bearer {TOKEN[:-1]}"},
    "longer": {"Authorization": f"Bearer {TOKEN}x"},
    "basic": {"Authorization": f"Basic {TOKEN}"},
    "bare": {"Authorization": TOKEN},
    "empty_bearer": {"Authorization": "Bearer "},
    "right": {"Authorization": f"Bearer {TOKEN}"},
    "right_lowercase_scheme": {"Authorization": f"bearer {TOKEN}"},
}

# (token configured, header) -> (status for a writable parameter, status otherwise)
EXPECTED = {
    (False, "none"): (403, 403),
    (False, "wrong"): (403, 403),
    (False, "right"): (403, 403),
    (True, "none"): (401, 401),
    (True, "basic"): (401, 401),
    (True, "bare"): (401, 401),
    (True, "empty_bearer"): (401, 401),
    (True, "wrong"): (403, 403),
    (True, "prefix"): (403, 403),
    (True, "longer"): (403, 403),
    (True, "right"): (200, 403),
    (True, "right_lowercase_scheme"): (200, 403),
}


@pytest.mark.parametrize(("configured", "header"), list(EXPECTED), ids=lambda v: str(v))
async def test_matrix(tmp_path: Path, configured: bool, header: str) -> None:
    token = TOKEN if configured else None
    async with service(tmp_path, token=token) as svc:
        drive = svc.sim.drives[1]
        for (parameter, pnu, value, raw), expected in zip(
            (WRITABLE, NOT_WRITABLE), EXPECTED[configured, header], strict=True
        ):
            before = drive.value(pnu)
            r = await svc.put("fan1", parameter, {"value": value}, headers=HEADERS[header])
            assert r.status_code == expected, r.text
            if expected == 200:
                assert drive.value(pnu) == raw
                assert [w.value for w in svc.audit_writer.writes(1, pnu)] == [raw]
                continue
            body = r.json()["error"]
            assert body["kind"] in {
                "unauthenticated",
                "forbidden",
                "writes_disabled",
                "not_writable",
            }
            assert TOKEN not in r.text
            assert drive.value(pnu) == before
            assert svc.audit_writer.for_pnu(1, pnu) == []  # not even the pre-read
            if expected == 401:
                assert body["kind"] == "unauthenticated"
            elif not configured:
                assert body["kind"] == "writes_disabled"
        # nothing written anywhere on the line but the one allowed write
        allowed = 1 if EXPECTED[configured, header][0] == 200 else 0
        assert len(svc.audit_writer.writes()) == allowed
        assert svc.audit is not None
        rows = svc.audit.latest(10)
        # one row per attempt with the token; those without one are counted per address
        # and minute (two rows if the minute turned between them)
        assert sum(r.count or 1 for r in rows) == 2
        assert {r.outcome for r in rows} <= {"ok", "refused"}
        assert sum(r.outcome == "ok" for r in rows) == allowed
        unauthenticated = EXPECTED[configured, header][0] in (401, 403) and header != "right"
        counted = [r for r in rows if r.count is not None]
        assert bool(counted) == (unauthenticated or not configured)
        assert all(r.token_id is None and r.drive == "" for r in counted)


async def test_reads_need_no_token(tmp_path: Path) -> None:
    async with service(tmp_path, token=None) as svc:
        r = await svc.client.get("/api/v1/drives/fan1/parameters/3-41")
        assert r.status_code == 200
        assert r.json()["value"] == 5  # the simulator's initial 5.00 s
