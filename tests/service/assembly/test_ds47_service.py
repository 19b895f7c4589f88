"""The service over simulated DP-V1 slaves whose PPO has no PKW words (PPO 3): every
parameter through PROFIdrive data record 47, the due polls of a slave in one request.

Every test also checks the wire: each Data_Exchange's control word was 0 (bit 10
clear), so the service never took control of a drive.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
from prometheus_client import generate_latest

from pkwbus.protocol import pzd
from pkwbus.protocol.profibus.dp.slave import RestartReason
from pkwbus.protocol.profibus.dpv1.msac import C1_SAP, C1Function, decode_c1_request
from pkwbus.protocol.profidrive.drive import decode_request
from pkwbus.protocol.profidrive.parameters import RequestId
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.audit.log import AuditLog
from pkwbus.service.config import parse_config
from pkwbus.service.http.api import create_app
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming
from pkwbus.sim.profibus.line import DpSimulator
from tests.master.wires.profibus.frame_log import FrameLog, log_frames

TOKEN = "s3cret-Write-Token-0123456789"
ADDRESSES = (8, 9, 10)
NAMES = {8: "mixer", 9: "pump", 10: "fan"}
POLLED = ("r0021", "r0027", "r0032", "p1120", "p1121", "p1082")


def config_text(url: str, audit: Path, extra: str = "", keys: str = "catalog: siemens-g120") -> str:
    polls = ", ".join(f'{{parameter: "{p}", every: 100ms}}' for p in POLLED)
    drives = "\n".join(
        f"""      - name: {NAMES[a]}
        address: {a}
        dialect: profidrive
        ppo: 3
        ident: 0x80B5
        dpv1: true
        {keys}
        poll: [{polls}{extra}]
        writable: ["p1121"]"""
        for a in ADDRESSES
    )
    return f"""
audit_db: {audit}
api:
  write_token_env: TEST_TOKEN
lines:
  - name: dp
    port: {url}
    protocol: profibus
    baudrate: 93750
    # The simulated slaves answer within a millisecond, from the test's own event loop: a
    # loaded machine holding that loop 20 ms made timeouts of its own, slaves taken for
    # down and parametrised again until the start's polls had not come in 30 s. Not more:
    # the master listens 10 slot times before it takes the bus, at every start.
    slot_time: 50ms
    watchdog: 2s
    alarms: off  # the tests count the parameters of each request
    counters: off
    drives:
{drives}
"""


@dataclass
class Service:
    sim: DpSimulator
    wire: FrameLog
    runtime: Runtime
    client: httpx.AsyncClient
    audit: AuditLog

    def sample(self, name: str, **labels: str) -> float | None:
        want = [f'{k}="{v}"' for k, v in labels.items()]
        for line in generate_latest(self.runtime.registry).decode().splitlines():
            if line.startswith(name + "{") and all(w in line for w in want):
                return float(line.rsplit(" ", 1)[1])
        return None

    def reads(self, drive: str) -> float:
        return self.sample("pkwbus_jobs_total", drive=drive, kind="read", outcome="ok") or 0.0

    def record_writes(self, address: int) -> list[bytes]:
        """The data record 47 requests written to a slave, in order."""
        out = []
        for frame in self.wire.frames:
            if frame.da == address and frame.dsap == C1_SAP:
                request = decode_c1_request(frame.data)
                if request.function is C1Function.WRITE:
                    out.append(request.data)
        return out

    def assert_never_took_control(self) -> None:
        words = [
            int.from_bytes(f.data[:2], "big") for f in self.wire.data_exchanges() if f.dsap is None
        ]
        assert words, "no Data_Exchange went out"
        assert all(w == pzd.MONITORING_CTW and not pzd.takes_control(w) for w in words)


@asynccontextmanager
async def service(
    tmp_path: Path, extra: str = "", not_ready: int = 1, keys: str = "catalog: siemens-g120"
) -> AsyncIterator[Service]:
    async with AsyncExitStack() as stack:
        sim = DpSimulator(
            ADDRESSES, dialect="profidrive", ppo_number=3, catalog="siemens-g120",
            timing=SimTiming(response_delay=0.001), seed=7, dpv1=True, not_ready=not_ready,
        )  # fmt: skip
        wire = log_frames(sim)
        end = await sim.serve_tcp("127.0.0.1", 0)
        stack.push_async_callback(end.close)
        config = parse_config(
            config_text(end.url, tmp_path / "audit.sqlite", extra, keys),
            environ={"TEST_TOKEN": TOKEN},
        )
        runtime = await build_runtime(config)
        await runtime.start()
        stack.push_async_callback(runtime.stop)
        audit = AuditLog(config.audit_db)
        stack.callback(audit.close)
        app = create_app(runtime, audit=audit, write_token=TOKEN)
        client = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://pkwbus.test", timeout=30.0
        )
        stack.push_async_callback(client.aclose)
        svc = Service(sim, wire, runtime, client, audit)
        await until(lambda: all(svc.reads(n) >= 2 * len(POLLED) for n in NAMES.values()))
        yield svc
        svc.assert_never_took_control()


async def until(condition: Callable[[], bool], timeout: float = 30.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not condition():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.01)


def f32(raw: int) -> float:
    return float(struct.unpack(">f", raw.to_bytes(4, "big"))[0])


async def test_the_due_polls_of_a_slave_go_out_in_one_request(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        for address, name in NAMES.items():
            drive = svc.sim.drives[address]
            # A parameter the simulated drive holds (not a live one): exactly its value.
            exported = svc.sample("pkwbus_parameter_value", drive=name, parameter="p1120")
            assert exported is not None
            assert exported == f32(drive.params.value(1120))
            assert svc.sample("pkwbus_drive_up", drive=name) == 1

            # The polls went out together: requests of all six value reads, once each
            # parameter's description settled.
            def sizes(address: int = address) -> list[int]:
                return [
                    len(r.addresses)
                    for r in map(decode_request, svc.record_writes(address))
                    if r.request_id is RequestId.READ and r.addresses[0].attribute == 0x10
                ]

            await until(lambda: sizes().count(len(POLLED)) >= 3)
            assert max(sizes()) == len(POLLED)
        # The live list: each slave in data exchange, its ident and owner from its diagnosis.
        view = {d["name"]: d for d in (await svc.client.get("/api/v1/drives")).json()}
        for name in NAMES.values():
            dp = view[name]["dp"]
            assert dp["state"] == "data_exchange" and dp["ident"] == 0x80B5
            assert dp["owner"] == 2 and dp["diagnosed"] is not None
        # "Not ready" answers were read again: more record reads than writes.
        reads = [
            f for f in svc.wire.frames
            if f.dsap == C1_SAP and decode_c1_request(f.data).function is C1Function.READ
        ]  # fmt: skip
        writes = sum(len(svc.record_writes(a)) for a in ADDRESSES)
        assert len(reads) > writes  # each response was read again at least once


async def test_a_write_goes_through_the_record_and_is_read_back(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        r = await svc.client.put(
            "/api/v1/drives/pump/parameters/p1121",
            json={"value": 12.15},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )
        assert r.status_code == 200, r.text
        assert r.json()["access"] == "ds47"
        assert r.json()["value"] is None  # a change in data record 47 is not echoed
        assert abs(svc.sim.drives[9].params.number(1121) - 12.15) < 1e-5
        assert svc.sim.drives[8].params.number(1121) != svc.sim.drives[9].params.number(1121)
        (row,) = [e for e in svc.audit.latest(10) if e.drive == "pump"]
        assert row.outcome == "ok" and row.parameter == "p1121"
        changes = [
            r
            for r in map(decode_request, svc.record_writes(9))
            if r.request_id is not RequestId.READ
        ]
        assert len(changes) == 1 and changes[0].addresses[0].pnu == 1121
        got = await svc.client.get("/api/v1/drives/pump/parameters/p1121")
        assert got.status_code == 200 and got.json()["access"] == "ds47"
        assert abs(got.json()["value"] - 12.15) < 1e-5
        # The next poll reads the new value back.
        await until(
            lambda: abs(
                (svc.sample("pkwbus_parameter_value", drive="pump", parameter="p1121") or 0) - 12.15
            ) < 1e-5
        )  # fmt: skip
        # With verify, the answer gives the value the read-back confirmed (README: the value
        # is null only without verify).
        r = await svc.client.put(
            "/api/v1/drives/pump/parameters/p1121",
            json={"value": 12.5, "verify": True},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )
        assert r.status_code == 200, r.text
        assert r.json()["verified"] is True and abs(r.json()["value"] - 12.5) < 1e-5


async def test_a_write_takes_the_type_the_drive_names_in_its_answers(tmp_path: Path) -> None:
    """No catalog and no description (describe: off): nothing but the drive's own answers,
    each naming its format (FloatingPoint), types p1121; a write uses that type."""
    async with service(tmp_path, keys="describe: off") as svc:
        info = [
            line for line in generate_latest(svc.runtime.registry).decode().splitlines()
            if line.startswith("pkwbus_parameter_info") and 'parameter="p1121"' in line
        ]  # fmt: skip
        assert info and all('source="none"' in line for line in info)
        r = await svc.client.put(
            "/api/v1/drives/pump/parameters/p1121",
            json={"value": 12.5},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )
        assert r.status_code == 200, r.text
        assert svc.sim.drives[9].params.number(1121) == 12.5
        (change,) = [
            r for r in map(decode_request, svc.record_writes(9))
            if r.request_id is not RequestId.READ
        ]  # fmt: skip
        assert change.changes[0].format.name == "FLOAT"


async def test_an_unknown_parameter_is_refused_in_words_and_the_rest_still_read(
    tmp_path: Path,
) -> None:
    extra = ', {parameter: "r9999", every: 100ms}'
    async with service(tmp_path, extra) as svc:
        await until(
            lambda: (svc.sample("pkwbus_pkw_faults_total", drive="fan",
                                fault="Illegal parameter number") or 0) >= 1
        )  # fmt: skip
        assert svc.sample("pkwbus_parameter_value", drive="fan", parameter="p1120") == f32(
            svc.sim.drives[10].params.value(1120)
        )


async def test_a_slave_restarted_mid_request_comes_back_and_the_others_keep_polling(
    tmp_path: Path,
) -> None:
    async with service(tmp_path, not_ready=3) as svc:
        writes = len(svc.record_writes(9))
        svc.sim.restart(9)
        others = {n: svc.reads(n) for n in ("mixer", "fan")}
        pump = svc.reads("pump")
        await until(lambda: all(svc.reads(n) >= others[n] + 12 for n in others))
        await until(lambda: svc.reads("pump") >= pump + 12)
        assert svc.sim.slaves[9].dpv1  # parametrised again, with DP-V1 on
        assert len(svc.record_writes(9)) > writes
        restarts = [
            svc.sample("pkwbus_dp_restarts_total", drive="pump", reason=r.value) or 0
            for r in RestartReason
        ]
        assert sum(restarts) >= 1


async def test_a_write_to_a_slave_gone_silent_ends_at_its_deadline(tmp_path: Path) -> None:
    async with service(tmp_path, not_ready=3) as svc:
        loop = asyncio.get_running_loop()
        svc.sim.slaves[9].not_ready = 10**6  # the change's response never comes: no race
        change = svc.client.put(
            "/api/v1/drives/pump/parameters/p1121", json={"value": 12.5},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )  # fmt: skip
        task = asyncio.ensure_future(change)
        # The write's request is written, its response not yet read: the slave goes silent.
        await until(lambda: any(
            decode_request(r).request_id is RequestId.CHANGE for r in svc.record_writes(9)
        ))  # fmt: skip
        svc.sim.kill(9)
        started = loop.time()
        r = await asyncio.wait_for(task, 30)
        assert loop.time() - started < 15  # the job's deadline, not forever
        assert r.status_code == 504, r.text
        (row,) = [e for e in svc.audit.latest(10) if e.drive == "pump"]
        assert row.outcome == "timeout"
        svc.sim.slaves[9].not_ready = 3
        svc.sim.revive(9)
        pump = svc.reads("pump")
        await until(lambda: svc.reads("pump") >= pump + 6)  # back, polled again
