"""A configuration reloaded without a restart, through the real process (`pkwbus run` in a
subprocess), measured at the simulators: which telegrams reach them, and how many times the
service opened their ports."""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import signal
import sqlite3
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from pkwbus.protocol.buses import decode_adr
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.sim import SimTiming, Simulator
from tests.reliability.service import start_run

TOKEN = "r3load-T0ken-0815-abcdef"
OTHER_TOKEN = "an0ther-T0ken-4242-fedcba"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


@dataclass
class Heard:
    """The requests a simulator took: (loop time, address) each."""

    at: list[tuple[float, int]] = field(default_factory=list)

    def count(self, address: int, since: float = 0.0) -> int:
        return sum(1 for t, a in self.at if a == address and t >= since)

    def gaps(self, address: int, start: float, end: float) -> float:
        """The longest time between two requests to ``address`` from ``start`` to ``end``."""
        times = [start, *(t for t, a in self.at if a == address and start <= t <= end), end]
        return max(b - a for a, b in itertools.pairwise(times))


async def simulator(addresses: list[int]) -> tuple[Any, Heard]:
    sim = Simulator(
        "fc", addresses, timing=SimTiming(response_delay=0.002), catalog="danfoss-fc", seed=3
    )
    heard = Heard()
    answer = sim.answer
    loop = asyncio.get_running_loop()

    def hear(telegram: Telegram, now: float | None = None) -> Any:
        heard.at.append((loop.time(), decode_adr(sim.protocol, telegram.adr).address))
        return answer(telegram, now)

    sim.answer = hear  # type: ignore[method-assign]
    end = await sim.serve_tcp("127.0.0.1", 0)
    return end, heard


def drive(name: str, address: int, polls: list[str], every: str = "100ms", **extra: Any) -> Any:
    return {
        "name": name,
        "address": address,
        "catalog": "danfoss-fc",
        "poll": [{"parameter": p, "every": every} for p in polls],
        **extra,
    }


def line(name: str, url: str, drives: list[Any], **extra: Any) -> dict[str, Any]:
    # No alarm words, settings or logs beyond what a test polls: the tests count telegrams.
    return {
        "name": name, "port": url, "protocol": "fc", "baudrate": 115200, "timeout": "250ms",
        "retries": 1, "alarms": "off", "settings": "off", "events": "off", "counters": "off",
        **extra, "drives": drives,
    }  # fmt: skip


def write_config(path: Path, lines: list[dict[str, Any]], **top: Any) -> None:
    body = {"audit_db": "audit.sqlite", "api": {"write_token_env": "RELOAD_TOKEN"}, **top}
    path.write_text(json.dumps({**body, "lines": lines}, indent=1))


@dataclass
class Running:
    proc: asyncio.subprocess.Process
    client: httpx.AsyncClient
    log: Path
    tmp: Path

    async def until(self, check: Callable[[], bool], seconds: float = 30) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + seconds
        while not check():
            assert self.proc.returncode is None, self.log.read_text()
            assert loop.time() < deadline, f"not within {seconds} s:\n{self.log.read_text()}"
            await asyncio.sleep(0.05)

    async def metrics(self) -> str:
        return (await self.client.get("/metrics")).text

    async def hangup(self) -> None:
        """SIGHUP, and wait for the reload's log line."""
        before = self.log.read_text().count("reload:")
        self.proc.send_signal(signal.SIGHUP)
        await self.until(lambda: self.log.read_text().count("reload:") > before)

    def audit(self) -> list[tuple[str, str, str]]:
        with sqlite3.connect(self.tmp / "audit.sqlite") as db:
            rows = db.execute(
                "SELECT client, outcome, detail FROM writes WHERE parameter = 'reload'"
            ).fetchall()
        return [tuple(r) for r in rows]


@asynccontextmanager
async def running(tmp: Path, config: Path) -> AsyncIterator[Running]:
    env = {**os.environ, "RELOAD_TOKEN": TOKEN, "OTHER_TOKEN": OTHER_TOKEN}
    env.pop("PKWBUS_LISTEN", None)
    log = tmp / "stderr.log"
    proc, port = await start_run(["run", "--config", str(config)], log, env=env, cwd=tmp)
    try:
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}", timeout=30) as client:
            yield Running(proc, client, log, tmp)
    finally:
        if proc.returncode is None:
            proc.send_signal(signal.SIGTERM)
        await asyncio.wait_for(proc.wait(), 60)
    assert proc.returncode == 0
    assert "Traceback" not in log.read_text()


async def test_a_reload_reopens_the_changed_line_while_the_other_goes_on(tmp_path: Path) -> None:
    """Line b's bus settings change: it is closed and opened again alone; line a's port
    stays open (one connection at its simulator) and its polls go on without a gap."""
    end_a, heard_a = await simulator([1])
    end_b, heard_b = await simulator([1])
    config = tmp_path / "pkwbus.yaml"
    a = line("a", end_a.url, [drive("a1", 1, ["16-13"])])
    write_config(config, [a, line("b", end_b.url, [drive("b1", 1, ["16-13"])])])
    loop = asyncio.get_running_loop()
    try:
        async with running(tmp_path, config) as svc:
            await svc.until(lambda: heard_a.count(1) >= 10 and heard_b.count(1) >= 10)
            before = loop.time()
            await asyncio.sleep(1.0)
            usual = heard_a.gaps(1, before, loop.time())  # polls every 100 ms, as it runs here
            changed = line("b", end_b.url, [drive("b1", 1, ["16-13"])], timeout="300ms")
            write_config(config, [a, changed])
            start = loop.time()
            await svc.hangup()
            reloaded = loop.time()
            await svc.until(lambda: end_b.connections == 2 and heard_b.count(1, reloaded) > 0)
            await asyncio.sleep(1.0)
            assert end_a.connections == 1  # line a was never reopened
            # Line a's polls went on through the reload: no gap beyond the usual ones (a
            # reopen would take its port's back-off and the drive's identification).
            across = heard_a.gaps(1, start, loop.time())
            assert across <= max(3 * usual, 0.5), (usual, across)
            assert "line b reopened" in svc.log.read_text()
            metrics = await svc.metrics()
            assert "pkwbus_config_last_reload_successful 1.0" in metrics
            assert [(c, o) for c, o, _ in svc.audit()] == [("SIGHUP", "ok")]
    finally:
        await end_a.close()
        await end_b.close()


async def test_a_reload_adds_and_removes_drives_and_polls(tmp_path: Path) -> None:
    """Drives and polls added start and their series appear; removed ones stop and their
    series leave /metrics; the line's port stays open throughout. Through the API, with the
    write token; a change of audit_db is refused (it takes a restart) while the rest applies."""
    end, heard = await simulator([1, 2, 3])
    config = tmp_path / "pkwbus.yaml"
    first = [drive("d1", 1, ["16-13"]), drive("d2", 2, ["16-13"])]
    write_config(config, [line("l", end.url, first)])
    loop = asyncio.get_running_loop()
    try:
        async with running(tmp_path, config) as svc:
            await svc.until(lambda: heard.count(1) >= 5 and heard.count(2) >= 5)
            metrics = await svc.metrics()
            d2 = 'pkwbus_parameter_value{drive="d2",index="0",line="l",parameter="16-13"}'
            assert d2 in metrics
            second = [drive("d1", 1, ["16-13", "16-14"]), drive("d3", 3, ["16-13"])]
            write_config(config, [line("l", end.url, second)], audit_db="elsewhere.sqlite")
            refused = await svc.client.post("/api/v1/reload")
            assert refused.status_code == 401  # the write token is needed
            r = await svc.client.post("/api/v1/reload", headers=AUTH)
            assert r.status_code == 200, r.text
            body = r.json()
            assert body["loaded"] is True
            assert "line l: drive d2 removed" in body["changes"]
            assert "line l: drive d3 added" in body["changes"]
            assert "line l: drive d1: polls changed" in body["changes"]
            assert any(text.startswith("audit_db:") for text in body["refused"]), body
            after = loop.time()

            def shown(text: str) -> Callable[[], bool]:
                return lambda: text in latest[0]

            latest = [""]

            async def scrape() -> bool:
                latest[0] = await svc.metrics()
                return True

            series = 'pkwbus_parameter_value{{drive="{}",index="0",line="l",parameter="{}"}}'
            deadline = loop.time() + 30
            wanted = [series.format("d3", "16-13"), series.format("d1", "16-14")]
            while not all(text in latest[0] for text in wanted):
                assert loop.time() < deadline, latest[0]
                await scrape()
                await asyncio.sleep(0.1)
            text = latest[0]
            assert series.format("d2", "16-13") not in text  # its series left
            assert 'drive="d2"' not in text
            await asyncio.sleep(1.0)
            assert heard.count(2, after + 0.5) == 0  # nothing more goes out to it
            assert heard.count(1, after) > 0 and heard.count(3, after) > 0
            assert end.connections == 1  # the port stayed open
            assert (tmp_path / "audit.sqlite").exists()
            assert not (tmp_path / "elsewhere.sqlite").exists()
            assert [(c, o) for c, o, _ in svc.audit()] == [("127.0.0.1", "ok")]
    finally:
        await end.close()


async def test_a_broken_file_changes_nothing(tmp_path: Path) -> None:
    """A file with a problem: the running configuration goes on, the metric says 0, the API
    answers 422 with each problem at its place; the next good file loads."""
    end, heard = await simulator([1])
    config = tmp_path / "pkwbus.yaml"
    good = [line("l", end.url, [drive("d1", 1, ["16-13"])])]
    write_config(config, good)
    loop = asyncio.get_running_loop()
    try:
        async with running(tmp_path, config) as svc:
            await svc.until(lambda: heard.count(1) >= 5)
            broken = [line("l", end.url, [drive("d1", 1, ["16-13"])], baudrate="fast")]
            write_config(config, broken, log_format="xml")
            r = await svc.client.post("/api/v1/reload", headers=AUTH)
            assert r.status_code == 422, r.text
            error = r.json()["error"]
            assert error["kind"] == "invalid_configuration"
            places = " | ".join(error["problems"])
            assert "lines[0].baudrate" in places and "log_format" in places, places
            assert "pkwbus_config_last_reload_successful 0.0" in await svc.metrics()
            since = loop.time()
            await svc.until(lambda: heard.count(1, since) >= 5)  # the old one runs on
            assert end.connections == 1
            write_config(config, [line("l", end.url, [drive("d1", 1, ["16-13"], every="200ms")])])
            await svc.hangup()
            assert "pkwbus_config_last_reload_successful 1.0" in await svc.metrics()
            # the reload's row is completed by the audit's writer after its log line
            await svc.until(lambda: [o for _, o, _ in svc.audit()][-1:] != ["pending"])
            assert [o for _, o, _ in svc.audit()] == ["invalid", "ok"]
            assert "lines[0].baudrate" in svc.audit()[0][2]
    finally:
        await end.close()


async def test_a_reload_applies_tokens_and_maintenance(tmp_path: Path) -> None:
    """Another write token applies at once; ``maintenance: true`` added puts the drive in
    maintenance (no telegram to it at the simulator, the other goes on); a drive the API put
    in maintenance stays so across a reload."""
    end, heard = await simulator([1, 2])
    config = tmp_path / "pkwbus.yaml"
    drives = [drive("d1", 1, ["16-13"]), drive("d2", 2, ["16-13"])]
    write_config(config, [line("l", end.url, drives)])
    loop = asyncio.get_running_loop()
    try:
        async with running(tmp_path, config) as svc:
            await svc.until(lambda: heard.count(1) >= 5 and heard.count(2) >= 5)
            r = await svc.client.put(
                "/api/v1/drives/d2/maintenance", json={"on": True, "reason": "fitter"}, headers=AUTH
            )
            assert r.status_code == 200, r.text
            held = [drive("d1", 1, ["16-13"], maintenance=True), drive("d2", 2, ["16-13"])]
            write_config(config, [line("l", end.url, held)], api={"write_token_env": "OTHER_TOKEN"})
            r = await svc.client.post("/api/v1/reload", headers=AUTH)
            assert r.status_code == 200, r.text
            since = loop.time() + 0.5
            await asyncio.sleep(1.5)
            assert heard.count(1, since) == 0 and heard.count(2, since) == 0
            metrics = await svc.metrics()
            held = 'pkwbus_drive_maintenance{{drive="{}",line="l",reason="{}"}} 1.0'
            assert held.format("d1", "configuration") in metrics
            assert held.format("d2", "fitter") in metrics
            old = await svc.client.post("/api/v1/reload", headers=AUTH)
            assert old.status_code == 403, old.text  # the old token no longer writes
            other_env = {"write_token_env": "OTHER_TOKEN"}
            write_config(config, [line("l", end.url, drives)], api=other_env)
            other = {"Authorization": f"Bearer {OTHER_TOKEN}"}
            r = await svc.client.post("/api/v1/reload", headers=other)
            assert r.status_code == 200, r.text
            back = loop.time()
            await svc.until(lambda: heard.count(1, back) >= 3)  # out of maintenance
            assert heard.count(2, back + 0.5) == 0  # the API's maintenance stays
    finally:
        await end.close()
