"""A real full file system under the audit database: `pkwbus run` refuses writes with a
503 and a JSON reason, puts nothing on the wire, counts it, says so on /readyz, logs
one line per refused write without a traceback, and writes again once there is room.

The file system is a small tmpfs mounted for the test (root only; skipped where it
cannot be mounted). tests/service/http/test_audit_store.py covers the same rules everywhere,
with the failure made at the SQLite connection.
"""

from __future__ import annotations

import signal
from pathlib import Path

from prometheus_client.parser import text_string_to_metric_families

from pkwbus.sim import SimTiming, Simulator

from .helpers import fill, record_wire, tmpfs
from .service import TOKEN, Service

WRITE = "/api/v1/drives/l1_d1/parameters/3-41"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def audit_errors(text: str) -> float:
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name == "pkwbus_audit_errors_total" and sample.labels == {"stage": "attempt"}:
                return sample.value
    raise AssertionError("no pkwbus_audit_errors_total{stage='attempt'}")


async def test_a_full_audit_file_system_refuses_writes_and_sends_nothing(tmp_path: Path) -> None:
    with tmpfs(tmp_path / "small", "1m") as fs:
        sim = Simulator("fc", [1], timing=SimTiming(0.002), seed=1, catalog="danfoss-fc")
        wire = record_wire(sim)
        end = await sim.serve_tcp("127.0.0.1", 0)
        service = Service(tmp_path, end.url, audit_db=fs / "audit.sqlite")
        try:
            await service.start()
            async with service.client() as client:
                r = await client.put(WRITE, json={"value": 12.0}, headers=AUTH)
                assert r.status_code == 200, r.text
                assert wire.writes[1] == 1
                before = sim.drives[1].value(341)

                filler = fill(fs)
                for _ in range(3):
                    r = await client.put(WRITE, json={"value": 38}, headers=AUTH)
                    assert r.status_code == 503, r.text
                    assert r.headers["content-type"] == "application/json"
                    error = r.json()["error"]
                    assert error["kind"] == "audit_unavailable"
                    assert "full" in error["message"]
                assert wire.writes[1] == 1, "a write went on the wire without its audit row"
                assert sim.drives[1].value(341) == before
                assert audit_errors((await client.get("/metrics")).text) == 3
                ready = await client.get("/readyz")
                assert ready.status_code == 503
                assert ready.json()["writes"] is False
                assert "full" in ready.json()["reason"]

                filler.unlink()  # room again: the next write is stored, sent, and ready again
                r = await client.put(WRITE, json={"value": 38}, headers=AUTH)
                assert r.status_code == 200, r.text
                assert r.json()["audit"] == "complete"
                assert wire.writes[1] == 2
                assert sim.drives[1].value(341) == 3800
                assert (await client.get("/readyz")).status_code == 200
            service.signal(signal.SIGTERM)
            assert await service.wait(10.0) == 0
        finally:
            await service.stop()
            await end.close()
    log = service.log.read_text()
    assert "Traceback" not in log
    refused = [line for line in log.splitlines() if "nothing was sent" in line]
    assert len(refused) == 3, log
    assert "audit log records again" in log
