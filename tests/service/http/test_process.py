"""The real thing: `pkwbus run` in a subprocess on a loopback port, over a simulator's TCP end."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
from pathlib import Path

import httpx

from pkwbus.protocol.buses import decode_adr
from pkwbus.sim import SimTiming, Simulator
from tests.reliability.service import start_run
from tests.service.http.conftest import TOKEN, line_yaml


async def test_pkwbus_run_writes_and_audits(tmp_path: Path) -> None:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), catalog="danfoss-fc")
    end = await sim.serve_tcp("127.0.0.1", 0)
    drives = [
        {
            "name": f"fan{a}",
            "address": a,
            "catalog": "danfoss-fc",
            "poll": [("16-13", "100ms"), ("3-41", "100ms")],  # 3-41: the old value
            "writable": ["3-41"],
        }
        for a in (1, 2)
    ]
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        "\n".join(
            [
                "audit_db: var/audit.sqlite",  # relative: to the working directory
                "lines:",
                line_yaml("line1", end.url, "fc", drives, timeout=0.2, retries=2),
            ]
        )
    )
    env = {**os.environ, "PKWBUS_WRITE_TOKEN": TOKEN}
    env.pop("PKWBUS_LISTEN", None)
    log = tmp_path / "stderr.log"
    proc, port = await start_run(
        ["--debug", "run", "--config", str(config)], log, env=env, cwd=tmp_path
    )
    try:
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            loop = asyncio.get_running_loop()
            deadline = loop.time() + 60
            while True:
                assert proc.returncode is None, "pkwbus run ended early"
                try:
                    ready = (await client.get("/readyz")).status_code == 200
                    drives = (await client.get("/api/v1/drives")).json() if ready else []
                    # ready, and fan2's 3-41 polled once: it is the write's old value
                    polled = [{v["parameter"] for v in d["values"]} for d in drives]
                    if drives and all({"16-13", "3-41"} <= p for p in polled):
                        break
                except httpx.TransportError:
                    pass
                assert loop.time() < deadline, "pkwbus run did not become ready"
                await asyncio.sleep(0.1)
            url = "/api/v1/drives/fan2/parameters/3-41"
            r = await client.put(
                url, json={"value": 17.5}, headers={"Authorization": f"Bearer {TOKEN}"}
            )
            assert r.status_code == 200, r.text
            assert sim.drives[2].value(341) == 1750
            r = await client.put(url, json={"value": 1}, headers={"Authorization": "Bearer no"})
            assert r.status_code == 403
            r = await client.get(
                "/api/v1/audit", params={"limit": 5}, headers={"Authorization": f"Bearer {TOKEN}"}
            )
            assert [(e["outcome"], e["count"]) for e in r.json()] == [("refused", 1), ("ok", None)]
            r = await client.get("/metrics")
            assert "pkwbus_jobs_total" in r.text
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGTERM)
        await asyncio.wait_for(proc.wait(), 60)
        await end.close()
    logs = log.read_text()
    assert proc.returncode == 0, logs
    assert "writes allowed with the token" in logs
    assert "start-up objects kept out of the garbage collector" in logs  # serve() settles
    assert TOKEN not in logs
    db = tmp_path / "var" / "audit.sqlite"
    assert db.exists()
    for f in db.parent.iterdir():
        assert TOKEN.encode() not in f.read_bytes()
    audit = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "pkwbus",
        "audit",
        "--config",
        str(config),
        "--json",
        cwd=tmp_path,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(audit.communicate(), 60)
    assert audit.returncode == 0, err.decode()
    rows = json.loads(out)
    assert [(e["outcome"], e["new_value"], e["raw_value"]) for e in rows] == [
        ("refused", None, None),  # without a valid token: counted, not kept
        ("ok", 17.5, 1750),
    ]
    assert rows[1]["old_value"] == 5
    assert rows[1]["token_id"].startswith("hmac:")


async def test_pkwbus_run_puts_a_drive_in_maintenance_and_takes_it_back(tmp_path: Path) -> None:
    """Through the real process: no telegram reaches the drive at the simulator while it is
    in maintenance, the other goes on; out of it, it is polled again."""
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), catalog="danfoss-fc")
    heard: list[int] = []
    answer = sim.answer

    def hear(telegram: object, now: float | None = None) -> object:
        heard.append(decode_adr(sim.protocol, telegram.adr).address)  # type: ignore[attr-defined]
        return answer(telegram, now)  # type: ignore[arg-type]

    sim.answer = hear  # type: ignore[method-assign,assignment]
    end = await sim.serve_tcp("127.0.0.1", 0)
    drives = [
        {"name": f"fan{a}", "address": a, "catalog": "danfoss-fc", "poll": [("16-13", "50ms")]}
        for a in (1, 2)
    ]
    config = tmp_path / "pkwbus.yaml"
    config.write_text(
        "\n".join(["audit_db: audit.sqlite", "lines:", line_yaml("line1", end.url, "fc", drives)])
    )
    env = {**os.environ, "PKWBUS_WRITE_TOKEN": TOKEN}
    env.pop("PKWBUS_LISTEN", None)
    proc, port = await start_run(["run", "--config", str(config)], tmp_path / "stderr.log",
                                 env=env, cwd=tmp_path)  # fmt: skip
    auth = {"Authorization": f"Bearer {TOKEN}"}
    loop = asyncio.get_running_loop()

    async def until(check: object, seconds: float = 30) -> None:
        deadline = loop.time() + seconds
        while not check():  # type: ignore[operator]
            assert loop.time() < deadline, "not within the time"
            await asyncio.sleep(0.05)

    try:
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            await until(lambda: heard.count(1) >= 3 and heard.count(2) >= 3)
            url = "/api/v1/drives/fan1/maintenance"
            r = await client.put(url, json={"on": True, "reason": "motor swap"}, headers=auth)
            assert r.status_code == 200, r.text
            since = len(heard)
            await until(lambda: heard[since:].count(2) >= 20)
            assert 1 not in heard[since:]
            metrics = (await client.get("/metrics")).text
            assert (
                'pkwbus_drive_maintenance{drive="fan1",line="line1",reason="motor swap"} 1.0'
                in (metrics)
            )
            r = await client.put(url, json={"on": False}, headers=auth)
            assert r.status_code == 200, r.text
            back = len(heard)
            await until(lambda: heard[back:].count(1) >= 3)
            assert "pkwbus_drive_maintenance{" not in (await client.get("/metrics")).text
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGTERM)
        await asyncio.wait_for(proc.wait(), 60)
        await end.close()
    assert proc.returncode == 0
