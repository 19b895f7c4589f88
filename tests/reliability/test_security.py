"""Security: writes without the token never reach the line; the token never shows in the
logs, the audit database or an error; the container runs as a user other than root."""

from __future__ import annotations

import re
import signal
from pathlib import Path

from pkwbus.sim import SimTiming, Simulator

from .helpers import record_wire
from .service import TOKEN, Service

WRITE = "/api/v1/drives/l1_d1/parameters/3-41"
ROOT = Path(__file__).resolve().parents[2]


async def test_writes_need_the_token_and_the_token_never_shows(tmp_path: Path) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(0.002), seed=1, catalog="danfoss-fc")
    wire = record_wire(sim)
    end = await sim.serve_tcp("127.0.0.1", 0)
    service = Service(tmp_path, end.url, extra=("--debug",))
    bodies: list[str] = []
    try:
        await service.start()
        async with service.client() as client:
            refused = [
                ({}, 401),
                ({"Authorization": f"Bearer {TOKEN[:-1]}"}, 403),
                ({"Authorization": f"Bearer {TOKEN}x"}, 403),
                ({"Authorization": f"Bearer {TOKEN.upper()}"}, 403),
                ({"Authorization": f"Basic {TOKEN}"}, 401),
                ({"Authorization": TOKEN}, 401),
                ({"Authorization": "Bearer"}, 401),
            ]
            for headers, status in refused:
                response = await client.put(WRITE, json={"value": 12.0}, headers=headers)
                assert response.status_code == status, (headers, response.text)
                bodies.append(response.text)
            good = {"Authorization": f"Bearer {TOKEN}"}
            for url, body, status in (
                ("/api/v1/drives/l1_d1/parameters/16-13", {"value": 1}, 403),  # not writable
                (WRITE, {"value": 1e9}, 422),  # beyond the catalog's limits
                (WRITE, {"value": "fast"}, 422),
            ):
                response = await client.put(url, json=body, headers=good)
                assert response.status_code == status, response.text
                bodies.append(response.text)
            assert wire.writes[1] == 0, "a refused write reached the line"
            response = await client.put(WRITE, json={"value": 12.0}, headers=good)
            assert response.status_code == 200, response.text
            bodies.append(response.text)
            assert wire.writes[1] == 1
            bodies.append((await client.get("/api/v1/audit", headers=good)).text)
            bodies.append((await client.get("/metrics")).text)
        service.signal(signal.SIGTERM)
        assert await service.wait(5.0) == 0
    finally:
        await service.stop()
        await end.close()
    secrets = (TOKEN, TOKEN[:-1], TOKEN.upper())
    log = service.log.read_text()
    assert "writes allowed with the token" in log
    for text in (log, *bodies):
        for secret in secrets:
            assert secret not in text
    for db in tmp_path.glob("audit.sqlite*"):  # the database, its WAL and shared memory
        data = db.read_bytes()
        for secret in secrets:
            assert secret.encode() not in data, db


def test_the_container_runs_as_a_user_other_than_root() -> None:
    text = (ROOT / "Dockerfile").read_text()
    stages = re.split(r"(?im)^\s*FROM\s", text)
    final = stages[-1]
    users = re.findall(r"(?im)^\s*USER\s+(\S+)", final)
    assert users, "the final stage sets no USER: it runs as root"
    user, _, group = users[-1].partition(":")
    assert user not in ("root", "0"), users[-1]
    assert group not in ("root", "0"), users[-1]
