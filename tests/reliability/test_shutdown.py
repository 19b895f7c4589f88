"""Shutdown: SIGTERM during a write finishes it or reports it cancelled; SIGKILL keeps the audit
database intact."""

from __future__ import annotations

import asyncio
import signal
import sqlite3
from pathlib import Path

import pytest

from pkwbus.service.audit.log import AuditLog
from pkwbus.sim import SimFaults, SimTiming, Simulator

from .service import TOKEN, Service, wait_for

AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
async def test_a_stop_signal_during_a_write(tmp_path: Path, sig: signal.Signals) -> None:
    if signal.getsignal(sig) is signal.SIG_IGN:  # started under nohup: the service inherits it
        pytest.skip(f"{sig.name} is ignored here, and pkwbus rightly keeps an ignored one so")
    sim = Simulator("fc", [1], seed=1, catalog="danfoss-fc")
    end = await sim.serve_tcp("127.0.0.1", 0)
    service = Service(tmp_path, end.url, timeout="3s")
    try:
        await service.start()
        # From now on the drive answers 0.8 s late, every answer (the background exchanges'
        # too); not before, where its ~45 start-up exchanges (identity, descriptions) would
        # take 36 s at that pace. A fault, not SimTiming: a connection reads that once.
        sim.set_faults(1, SimFaults(late=1.0, late_seconds=0.8))
        async with service.client() as client:
            write = asyncio.create_task(
                client.put(
                    "/api/v1/drives/l1_d1/parameters/3-41", json={"value": 12.5}, headers=AUTH
                )
            )
            # The write reads the old value first (0.8 s), then writes (0.8 s): mid-way
            # through, one of the two is on the wire.
            await asyncio.sleep(1.2)
            assert not write.done()
            service.signal(sig)
            loop = asyncio.get_running_loop()
            sent = loop.time()
            response = await asyncio.wait_for(write, 5)
            assert await service.wait(5.0) == 0
            assert loop.time() - sent < 5.0
        assert response.status_code in (200, 503), response.text
        with sqlite3.connect(service.audit_db) as db:
            rows = db.execute("SELECT outcome, detail FROM writes").fetchall()
        assert len(rows) == 1
        outcome, _detail = rows[0]
        assert outcome == ("ok" if response.status_code == 200 else "cancelled"), rows
        log = service.log.read_text()
        assert "Traceback" not in log
        assert f"stopping ({sig.name})" in log and "stopped" in log, log
    finally:
        await service.stop()
        await end.close()


async def test_sigkill_during_writes_leaves_the_audit_database_intact(tmp_path: Path) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.05), seed=1, catalog="danfoss-fc")
    end = await sim.serve_tcp("127.0.0.1", 0)
    service = Service(tmp_path, end.url, timeout="1s")
    try:
        await service.start()
        async with service.client() as client:
            writes = [
                asyncio.create_task(
                    client.put(
                        "/api/v1/drives/l1_d1/parameters/3-41",
                        json={"value": 10 + i},
                        headers=AUTH,
                    )
                )
                for i in range(20)
            ]

            def one_answered() -> bool:
                return any(
                    w.done() and not w.exception() and w.result().status_code == 200 for w in writes
                )

            await wait_for(one_answered, 20)  # then killed with the others on their way
            service.signal(signal.SIGKILL)
            await service.wait(5.0)
            await asyncio.gather(*writes, return_exceptions=True)
        with sqlite3.connect(service.audit_db) as db:
            assert db.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
        audit = AuditLog(service.audit_db)
        try:
            rows = audit.latest(100)
        finally:
            audit.close()
        assert rows, "no write reached the audit log before the kill"
        assert {r.drive for r in rows} == {"l1_d1"}
        assert any(r.outcome == "ok" for r in rows)
        # Restarted on the same database, the service records the next write after them.
        await service.start()
        async with service.client() as client:
            ok = await client.put(
                "/api/v1/drives/l1_d1/parameters/3-41", json={"value": 7}, headers=AUTH
            )
            assert ok.status_code == 200, ok.text
            latest = (await client.get("/api/v1/audit?limit=1", headers=AUTH)).json()
        assert latest[0]["id"] == max(r.id or 0 for r in rows) + 1
        assert latest[0]["outcome"] == "ok"
        service.signal(signal.SIGTERM)
        assert await service.wait(5.0) == 0
    finally:
        await service.stop()
        await end.close()
