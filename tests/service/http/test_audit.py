"""The audit log: one row per attempt with its outcome, no token, kept across restarts;
requests without a valid token as one counted row per address and minute."""

from __future__ import annotations

import asyncio
import hashlib
import hmac
import itertools
import json
import sqlite3
from pathlib import Path

import pytest

from pkwbus.cli import main
from pkwbus.protocol.pkw import PkwRequest, PkwResponse
from pkwbus.service.audit.log import AuditEntry, AuditError, AuditLog, as_dict
from tests.service.http.conftest import AUTH, POLLED_WRITABLES, TOKEN, fc_drives, service

WRONG = "Bearer guess-of-the-token-XYZ"
NOW = 1_700_000_000.0  # the audit's clock in these tests: every attempt in one minute


async def attempts(tmp_path: Path) -> list[tuple[str, int]]:
    """Every kind of attempt once; returns (expected outcome, status) in order."""
    done: list[tuple[str, int]] = []
    async with service(tmp_path, fc=fc_drives(polls=POLLED_WRITABLES)) as svc:
        assert svc.audit is not None
        ticks = itertools.count()  # a millisecond a look: the attempts in order, in one minute
        svc.audit.clock = lambda: NOW + next(ticks) / 1000
        drive3 = svc.sim.drives[3]

        def clamp(address: int, req: PkwRequest, resp: PkwResponse) -> None:
            if address == 3 and req.is_write and req.pnu == 342:
                drive3.set_value(342, 111)

        svc.audit_writer.after.append(clamp)
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
            # a dead drive: the read before the change gets no answer, nothing is sent
            ("not_sent", "fan3", "3-41", {"value": 1}, AUTH),
        ]
        for outcome, drive, parameter, body, headers in steps:
            if outcome == "not_sent":
                svc.sim.kill(3)
            r = await svc.put(drive, parameter, body, headers=headers)
            done.append((outcome, r.status_code))
        r = await svc.client.get("/api/v1/audit", params={"limit": 3}, headers=AUTH)
        assert r.status_code == 200
        latest = r.json()
        assert [e["outcome"] for e in latest] == ["not_sent", "ok", "mismatch"]
        r = await svc.client.get("/api/v1/audit", headers=AUTH)
        assert len(r.json()) == len(steps) - 1  # the two without a valid token share a row
        for bad in ("0", "-1", "1001", "10001", "x"):
            r = await svc.client.get("/api/v1/audit", params={"limit": bad}, headers=AUTH)
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
        same_id = log.token_id(TOKEN)  # the key beside the database: the same id
    finally:
        log.close()
    # one row per attempt with the token; the two without share one counted row, in
    # time order, written (a later id) once the log was read or closed
    expected = [o for o, _ in done[:3]] + [o for o, _ in done[4:]]
    assert [r.outcome for r in rows] == expected
    assert [r.time for r in rows] == sorted(r.time for r in rows)
    assert sorted(r.id for r in rows) == list(range(1, len(expected) + 1))
    ok, rejected, refusals, not_writable, *_ = rows
    assert (ok.old_value, ok.new_value, ok.raw_value, ok.store) == (5, 11.5, 1150, "ram")
    assert (rejected.fault, rejected.raw_value) == (17, 500)
    assert rejected.old_value is not None
    assert (refusals.count, refusals.token_id, refusals.drive, refusals.parameter) == (
        2,
        None,
        "",
        "",
    )
    assert refusals.detail is not None and "unauthenticated 1" in refusals.detail
    assert "forbidden 1" in refusals.detail
    assert all(r.count is None for r in rows if r is not refusals)
    assert not_writable.token_id == same_id and same_id.startswith("hmac:")
    assert all(r.client == "127.0.0.1" for r in rows)
    assert all(r.time > 0 for r in rows)
    eeprom = rows[9]
    assert (eeprom.store, eeprom.raw_value, eeprom.old_value) == ("eeprom", 3000, 5)
    unsent = rows[10]
    assert unsent.old_value == 5 and unsent.raw_value == 100  # polled before it died
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
    assert [e["outcome"] for e in out] == list(reversed(expected))[:5]
    assert main(["audit", "--config", str(config)]) == 0
    text = capsys.readouterr().out.splitlines()
    assert text[0].split()[:4] == ["TIME", "DRIVE", "PARAMETER", "CHANGE"]
    assert len(text) == 1 + len(expected)
    assert text[-2].split()[1:3] == ["fan1", "1-20"] and "rejected fault 17" in text[-2]
    assert "2 request(s)" in text[-3] and "refused" in text[-3]
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
    from tests.service.http.conftest import USS_DRIVES

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


def test_the_token_id_is_keyed_with_a_secret_beside_the_database(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "audit.sqlite"
    key = tmp_path / "audit.sqlite.key"
    log = AuditLog(path)
    first = log.token_id(TOKEN)
    log.close()
    assert key.stat().st_mode & 0o777 == 0o600
    secret = bytes.fromhex(key.read_text())
    assert len(secret) == 32
    # an HMAC of the token with that secret: derivable with it ...
    expected = hmac.new(secret, TOKEN.encode(), hashlib.sha256).hexdigest()
    assert first == "hmac:" + expected[:16]
    # ... and not without it: no plain hash of the token, no id shared with another site
    plain = hashlib.sha256(TOKEN.encode()).hexdigest()
    assert plain[:12] not in first
    other = AuditLog(tmp_path / "other.sqlite")
    assert other.token_id(TOKEN) != first
    other.close()
    # the same id after a restart
    log = AuditLog(path)
    assert log.token_id(TOKEN) == first
    assert log.token_id(TOKEN + "x") != first
    log.close()


def test_a_look_at_the_audit_creates_no_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "audit.sqlite"
    log = AuditLog(path)
    log.record(AuditEntry("c", "fan1", "3-41", 0, "ok", new_value=1.0))
    log.close()
    key = tmp_path / "audit.sqlite.key"
    key.unlink()
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        f"audit_db: {path}\n"
        "lines:\n"
        "  - {name: l1, port: 'socket://127.0.0.1:9', protocol: fc, baudrate: 9600,\n"
        "     drives: [{name: d1, address: 1}]}\n"
    )
    assert main(["audit", "--config", str(config), "--json"]) == 0
    assert [e["outcome"] for e in json.loads(capsys.readouterr().out)] == ["ok"]
    look = AuditLog(path, readonly=True)
    assert look.latest(1)[0].outcome == "ok"
    look.close()
    assert not key.exists()


def test_a_damaged_key_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "audit.sqlite"
    AuditLog(path).close()
    (tmp_path / "audit.sqlite.key").write_text("not a key\n")
    with pytest.raises(AuditError, match=r"key file .* is damaged"):
        AuditLog(path)


OLD_SCHEMA = """
CREATE TABLE writes (
    id INTEGER PRIMARY KEY AUTOINCREMENT, time REAL NOT NULL, client TEXT NOT NULL,
    token_id TEXT, drive TEXT NOT NULL, parameter TEXT NOT NULL,
    idx INTEGER NOT NULL DEFAULT 0, store TEXT, old_value TEXT, new_value TEXT,
    raw_value INTEGER, outcome TEXT NOT NULL, fault INTEGER, detail TEXT
);
INSERT INTO writes (time, client, drive, parameter, outcome) VALUES (1, 'c', 'fan1', '3-41', 'ok');
"""


def test_a_database_of_the_earlier_layout_is_read_and_extended(tmp_path: Path) -> None:
    path = tmp_path / "audit.sqlite"
    with sqlite3.connect(path) as db:
        db.executescript(OLD_SCHEMA)
    look = AuditLog(path, readonly=True)
    assert [(e.outcome, e.count) for e in look.latest(5)] == [("ok", None)]
    look.close()
    log = AuditLog(path)
    log.refused("10.0.0.1", "unauthenticated")
    assert [(e.outcome, e.count) for e in log.latest(5)] == [("refused", 1), ("ok", None)]
    log.close()
