"""The audit log: one row per attempt with its outcome, no token, kept across restarts."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from pkwbus.cli import main
from pkwbus.protocol.pkw import PkwRequest, PkwResponse
from pkwbus.service.audit import AuditEntry, AuditLog, as_dict, token_id
from tests.api.conftest import AUTH, POLLED_WRITABLES, TOKEN, fc_drives, service

WRONG = "Bearer guess-of-the-token-XYZ"


async def attempts(tmp_path: Path) -> list[tuple[str, int]]:
    """Every kind of attempt once; returns (expected outcome, status) in order."""
    done: list[tuple[str, int]] = []
    async with service(tmp_path, fc=fc_drives(polls=POLLED_WRITABLES)) as svc:
        drive3 = svc.sim.drives[3]

        def clamp(address: int, req: PkwRequest, resp: PkwResponse) -> None:
            if address == 3 and req.is_write and req.pnu == 342:
                drive3.set_value(342, 111)

        svc.recorder.after.append(clamp)
        steps = [
            ("ok", "fan1", "3-41", {"value": 11.5}, AUTH),
            ("rejected", "fan1", "1-20", {"value": 5000}, AUTH),
            ("refused", "fan1", "3-41", {"value": 1}, {}),
            ("refused", "fan1", "3-41", {"value": 1}, {"Authorization": WRONG}),
            ("refused", "fan1", "3-03", {"value": 1}, AUTH),
            ("invalid", "fan1", "3-41", {"value": -3}, AUTH),
            ("invalid", "fan1", "3-41", {"value": 1, "bogus": 1}, AUTH),
            ("invalid", "ghost", "3-41", {"value": 1}, AUTH),
            ("dry_run", "fan2", "3-42", {"value": 2, "dry_run": True}, AUTH),
            ("mismatch", "fan3", "3-42", {"value": 4, "verify": True}, AUTH),
            ("ok", "fan2", "3-41", {"value": 30, "store": "eeprom"}, AUTH),
            ("timeout", "fan3", "3-41", {"value": 1}, AUTH),
        ]
        for outcome, drive, parameter, body, headers in steps:
            if outcome == "timeout":
                svc.sim.kill(3)
            r = await svc.put(drive, parameter, body, headers=headers)
            done.append((outcome, r.status_code))
        r = await svc.client.get("/api/v1/audit", params={"limit": 3})
        assert r.status_code == 200
        latest = r.json()
        assert [e["outcome"] for e in latest] == ["timeout", "ok", "mismatch"]
        r = await svc.client.get("/api/v1/audit")
        assert len(r.json()) == len(steps)
        for bad in ("0", "-1", "10001", "x"):
            r = await svc.client.get("/api/v1/audit", params={"limit": bad})
            assert r.status_code == 422
    return done


async def test_one_row_per_attempt_kept_across_restart(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    caplog.set_level("DEBUG")
    done = await attempts(tmp_path)
    assert [s for _, s in done] == [200, 409, 401, 403, 403, 422, 422, 404, 200, 200, 200, 504]
    # the service is stopped and its audit log closed: open the file again
    path = tmp_path / "audit.sqlite"
    log = AuditLog(path)
    try:
        rows = list(reversed(log.latest(100)))
    finally:
        log.close()
    assert [r.outcome for r in rows] == [o for o, _ in done]
    assert [r.id for r in rows] == list(range(1, len(done) + 1))
    ok, rejected, no_token, wrong, not_writable, *_ = rows
    assert (ok.old_value, ok.new_value, ok.raw_value, ok.store) == (5, 11.5, 1150, "ram")
    assert (rejected.fault, rejected.raw_value) == (17, 500)
    assert rejected.old_value is not None
    assert no_token.token_id is None and wrong.token_id is None
    assert not_writable.token_id == token_id(TOKEN)
    assert all(r.client == "127.0.0.1" for r in rows)
    assert all(r.time > 0 for r in rows)
    eeprom = rows[10]
    assert (eeprom.store, eeprom.raw_value, eeprom.old_value) == ("eeprom", 3000, 5)
    timeout = rows[11]
    assert timeout.old_value == 5 and timeout.raw_value == 100  # polled before it died
    # neither the token nor a guess at it is kept or logged
    for f in tmp_path.glob("audit.sqlite*"):
        data = f.read_bytes()
        assert TOKEN.encode() not in data, f
        assert b"guess-of-the-token" not in data, f
    assert TOKEN not in caplog.text
    assert "guess-of-the-token" not in caplog.text

    # pkwbus audit --config FILE reads the same file
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        f"audit_db: {path}\n"
        "lines:\n"
        "  - {name: l1, port: 'socket://127.0.0.1:9', protocol: fc, baudrate: 9600,\n"
        "     drives: [{name: d1, address: 1}]}\n"
    )
    capsys.readouterr()
    assert main(["audit", "--config", str(config), "--json", "--limit", "5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [e["outcome"] for e in out] == [o for o, _ in reversed(done)][:5]
    assert main(["audit", "--config", str(config)]) == 0
    text = capsys.readouterr().out.splitlines()
    assert len(text) == len(done)
    assert "fan1 1-20" in text[-2] and "rejected fault 17" in text[-2]
    assert TOKEN not in "\n".join(text)


async def test_audit_cli_without_database(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        f"audit_db: {tmp_path / 'none.sqlite'}\n"
        "lines:\n"
        "  - {name: l1, port: 'socket://127.0.0.1:9', protocol: fc, baudrate: 9600,\n"
        "     drives: [{name: d1, address: 1}]}\n"
    )
    assert main(["audit", "--config", str(config)]) == 2
    assert "no audit database" in capsys.readouterr().err


async def test_concurrent_writes_to_different_drives(tmp_path: Path) -> None:
    from tests.api.conftest import USS_DRIVES

    async with service(tmp_path, uss=USS_DRIVES) as svc:
        targets = [
            ("fan1", "3-41", 21.0, 2100),
            ("fan2", "3-41", 22.0, 2200),
            ("fan3", "3-42", 23.0, 2300),
            ("fan1", "3-42", 24.0, 2400),
            ("pump1", "p1120", 25.5, None),
        ]
        results = await asyncio.gather(
            *(svc.put(d, p, {"value": v, "verify": True}) for d, p, v, _ in targets)
        )
        for r in results:
            assert r.status_code == 200, r.text
            assert r.json()["verified"] is True
        fc = svc.sims["fc"].drives
        assert fc[1].value(341) == 2100 and fc[2].value(341) == 2200
        assert fc[3].value(342) == 2300 and fc[1].value(342) == 2400
        uss = svc.sims["uss"].drives[1]
        assert uss.params.number(1120) == 25.5
        assert svc.audit is not None
        rows = svc.audit.latest(10)
        assert len(rows) == len(targets)
        assert {(r.drive, r.parameter, r.new_value) for r in rows} == {
            (d, p, v) for d, p, v, _ in targets
        }
        assert all(r.outcome == "ok" for r in rows)
        assert len({r.id for r in rows}) == len(targets)
        assert sorted(r.json()["audit_id"] for r in results) == sorted(r.id for r in rows)


def test_non_finite_values_stay_readable_as_json(tmp_path: Path) -> None:
    """A NaN kept as a float made GET /api/v1/audit fail (JSON has no NaN)."""
    log = AuditLog(tmp_path / "a.sqlite")
    try:
        for value in (float("nan"), float("inf"), -float("inf")):
            log.record(AuditEntry("c", "d", "p", 0, "invalid", new_value=value, old_value=value))
        rows = log.latest(10)
    finally:
        log.close()
    assert [r.new_value for r in rows] == ["-inf", "inf", "nan"]
    json.dumps([as_dict(r) for r in rows], allow_nan=False)


def test_rows_left_pending_by_a_killed_service_are_marked_interrupted(tmp_path: Path) -> None:
    path = tmp_path / "audit.sqlite"
    log = AuditLog(path)
    row = log.record(AuditEntry("c", "fan1", "3-41", 0, "pending", new_value=1.0))
    log.record(AuditEntry("c", "fan1", "3-41", 0, "ok", new_value=2.0))
    log.close()  # as a SIGKILL would leave it: one row still pending
    look = AuditLog(path, readonly=True)
    assert [e.outcome for e in look.latest(5)] == ["ok", "pending"]  # a look changes nothing
    look.close()
    log = AuditLog(path)
    assert log.close_interrupted() == 1
    entries = {e.id: e for e in log.latest(5)}
    log.close()
    assert entries[row].outcome == "interrupted"
    assert "may have applied" in (entries[row].detail or "")
