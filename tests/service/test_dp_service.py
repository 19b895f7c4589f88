"""The service over simulated PROFIBUS DP slaves on TCP: values, writes, restarts, dead slaves.

Every test also checks the wire: each PPO-write pkwbus sent had a control word
of 0 (bit 10 clear), so the service never took control of a drive.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import httpx
from prometheus_client import generate_latest

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol import fdl, ppo
from pkwbus.protocol.dp_services import Service
from pkwbus.protocol.dp_slave import SlaveState
from pkwbus.service.api import create_app
from pkwbus.service.audit import AuditLog
from pkwbus.service.build import build_runtime
from pkwbus.service.config import parse_config
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming
from pkwbus.sim.dp_line import DpSimulator
from pkwbus.sim.ends import TcpEnd
from tests.master.dp_wire import DpWire, record_dp_wire

TOKEN = "s3cret-Write-Token-0123456789"
ADDRESSES = (8, 9, 10)
NAMES = {8: "mixer", 9: "pump", 10: "fan"}


def config_text(url: str, audit: Path) -> str:
    drives = "\n".join(
        f"""      - name: {NAMES[a]}
        address: {a}
        dialect: danfoss-pcv
        ident: 0x0402
        catalog: danfoss-fc
        poll: [{{parameter: "3-41", every: 100ms}}, {{parameter: "16-13", every: 100ms}}]
        writable: ["3-41"]"""
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
    baudrate: 19200
    slot_time: 20ms
    watchdog: 2s
    drives:
{drives}
"""


@dataclass
class DpService:
    sim: DpSimulator
    wire: DpWire
    runtime: Runtime
    client: httpx.AsyncClient
    audit: AuditLog
    end: TcpEnd

    def metrics(self) -> str:
        return generate_latest(self.runtime.registry).decode()

    def sample(self, name: str, **labels: str) -> float | None:
        want = [f'{k}="{v}"' for k, v in labels.items()]
        for line in self.metrics().splitlines():
            if line.startswith(name + "{") and all(w in line for w in want):
                return float(line.rsplit(" ", 1)[1])
        return None

    def reads(self, drive: str) -> float:
        return self.sample("pkwbus_jobs_total", drive=drive, kind="read", outcome="ok") or 0.0

    def state(self, drive: str) -> SlaveState | None:
        for s in SlaveState:
            if self.sample("pkwbus_dp_slave_state", drive=drive, state=s.value) == 1:
                return s
        return None


@asynccontextmanager
async def dp_service(tmp_path: Path) -> AsyncIterator[DpService]:
    async with AsyncExitStack() as stack:
        sim = DpSimulator(
            ADDRESSES, dialect="danfoss-pcv", timing=SimTiming(response_delay=0.001), seed=5
        )
        wire = record_dp_wire(sim)
        end = await sim.serve_tcp("127.0.0.1", 0)
        env = {"TEST_TOKEN": TOKEN}
        config = parse_config(config_text(end.url, tmp_path / "audit.sqlite"), environ=env)
        runtime = await build_runtime(config)
        await runtime.start()
        stack.push_async_callback(runtime.stop)
        audit = AuditLog(config.audit_db)
        stack.callback(audit.close)
        app = create_app(runtime, audit=audit, write_token=config.write_token(env))
        client = httpx.AsyncClient(
            transport=httpx.ASGITransport(app=app), base_url="http://pkwbus.test", timeout=30.0
        )
        stack.push_async_callback(client.aclose)
        service = DpService(sim, wire, runtime, client, audit, end)
        stack.push_async_callback(lambda: service.end.close())
        await until(lambda: all(service.reads(n) >= 2 for n in NAMES.values()))
        yield service
        assert sim.ppo.length == ppo.ppo_type(1).length
        wire.assert_never_took_control(sim.ppo.length)


async def until(condition: Callable[[], bool], timeout: float = 30.0) -> None:
    """Until ``condition`` holds (generous: the machine may be loaded)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not condition():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.01)


async def test_values_in_metrics_are_the_simulators_scaled_by_the_catalog(
    tmp_path: Path,
) -> None:
    factor = ParameterDescription.from_spec(load_catalog("danfoss-fc").get(341)).scaling.factor
    assert factor == Fraction(1, 100)  # conversion index -2
    async with dp_service(tmp_path) as svc:
        for address, name in NAMES.items():
            raw = svc.sim.drives[address].params.value(341)
            exported = svc.sample("pkwbus_parameter_value", drive=name, parameter="3-41")
            assert exported == float(raw * factor)
            assert svc.sample("pkwbus_drive_up", drive=name) == 1
            assert svc.state(name) is SlaveState.DATA_EXCHANGE
            # The status word comes from the PZD of every cycle.
            assert svc.sample("pkwbus_drive_status_word", drive=name) is not None


async def test_a_write_through_the_api_reaches_its_slave_and_is_audited(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        before = {a: svc.sim.drives[a].params.value(341) for a in ADDRESSES}
        r = await svc.client.put(
            "/api/v1/drives/pump/parameters/3-41",
            json={"value": 12.5},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )
        assert r.status_code == 200, r.text
        assert svc.sim.drives[9].params.value(341) == 1250  # conversion index -2
        assert all(svc.sim.drives[a].params.value(341) == before[a] for a in (8, 10))
        (row,) = [e for e in svc.audit.latest(10) if e.drive == "pump"]
        assert row.outcome == "ok" and row.parameter == "3-41" and row.new_value == 12.5
        assert svc.sample("pkwbus_jobs_total", drive="pump", kind="write", outcome="ok") == 1


async def test_a_restarted_slave_is_parametrised_again_and_the_others_keep_polling(
    tmp_path: Path,
) -> None:
    async with dp_service(tmp_path) as svc:
        svc.sim.restart(9)
        await until(
            lambda: (svc.sample("pkwbus_dp_restarts_total", drive="pump", reason="prm_required")
                     or 0) + (svc.sample("pkwbus_dp_restarts_total", drive="pump", reason="rs")
                              or 0) + (svc.sample("pkwbus_dp_restarts_total", drive="pump",
                                                  reason="diag") or 0) >= 1
        )  # fmt: skip
        reads = svc.reads("pump")
        await until(lambda: svc.reads("pump") >= reads + 4)
        assert svc.state("pump") is SlaveState.DATA_EXCHANGE
        assert svc.sim.slaves[9] is not None


async def test_a_dead_slave_goes_offline_while_the_others_keep_their_poll_rate(
    tmp_path: Path,
) -> None:
    async with dp_service(tmp_path) as svc:
        svc.sim.kill(10)
        await until(lambda: svc.state("fan") is SlaveState.OFFLINE)
        assert svc.sample("pkwbus_drive_up", drive="fan") == 0
        dead_reads = svc.reads("fan")
        alive = {n: svc.reads(n) for n in ("mixer", "pump")}
        # While the fan is offline the others complete their polls; the fan none.
        await until(lambda: all(svc.reads(n) >= alive[n] + 10 for n in alive))
        assert svc.reads("fan") == dead_reads
        timeouts = svc.sample("pkwbus_telegram_errors_total", drive="fan", kind="timeout")
        assert timeouts is not None and timeouts >= 1
        # It comes back by itself.
        svc.sim.revive(10)
        await until(lambda: svc.state("fan") is SlaveState.DATA_EXCHANGE)
        await until(lambda: svc.reads("fan") >= dead_reads + 2)
        assert svc.sample("pkwbus_drive_up", drive="fan") == 1


async def test_a_write_while_its_slave_restarts_ends_with_a_clear_outcome(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        put = asyncio.ensure_future(
            svc.client.put(
                "/api/v1/drives/mixer/parameters/3-41",
                json={"value": 7.5},
                headers={"Authorization": f"Bearer {TOKEN}"},
            )
        )
        svc.sim.restart(8)
        r = await put
        (row,) = [e for e in svc.audit.latest(10) if e.drive == "mixer"]
        if r.status_code == 200:
            assert row.outcome == "ok" and svc.sim.drives[8].params.value(341) == 750
        else:
            assert r.status_code == 504 and row.outcome == "timeout", r.text
        await until(lambda: svc.state("mixer") is SlaveState.DATA_EXCHANGE)


async def test_port_loss_takes_every_slave_offline_and_back(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        end = svc.end
        port = end.port
        await end.close()
        await until(
            lambda: all(svc.sample("pkwbus_drive_up", drive=n) == 0 for n in NAMES.values())
        )
        assert all(svc.state(n) is SlaveState.OFFLINE for n in NAMES.values())
        assert svc.runtime.snapshot.lines["dp"] is False
        svc.end = await svc.sim.serve_tcp("127.0.0.1", port)
        reads = {n: svc.reads(n) for n in NAMES.values()}
        await until(lambda: all(svc.reads(n) >= reads[n] + 2 for n in NAMES.values()))
        assert all(svc.state(n) is SlaveState.DATA_EXCHANGE for n in NAMES.values())


async def test_stop_sends_global_control_clear_then_closes(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        await svc.runtime.stop()
        last = svc.wire.frames[-1]
        assert last.dsap == Service.GLOBAL_CONTROL and last.da == fdl.BROADCAST
        assert all(svc.sim.slaves[a].clears == 1 for a in ADDRESSES)
        assert svc.runtime.snapshot.lines["dp"] is False


MIXED = """
lines:
  - name: dp
    port: sim://profibus?drives=8,9
    protocol: profibus
    baudrate: 93750
    drives:
      - name: extruder
        address: 8
        dialect: danfoss-pcv
        ident: 0x0402
        catalog: danfoss-fc
        poll: [{parameter: "3-41", every: 200ms}]
      - name: blower
        address: 9
        dialect: profidrive
        ident: 0x80B5
        catalog: siemens-g120
        poll: [{parameter: p1120, every: 200ms}]
"""


async def test_a_sim_port_simulates_each_slave_in_its_own_dialect(tmp_path: Path) -> None:
    config = parse_config(MIXED + f"audit_db: {tmp_path / 'a.sqlite'}\n", environ={})
    runtime = await build_runtime(config)
    await runtime.start()
    try:
        readings = runtime.snapshot.readings
        await until(lambda: {("extruder", "3-41", 0), ("blower", "p1120", 0)} <= readings.keys())
        assert all(s.up for s in runtime.snapshot.drives.values())
    finally:
        await runtime.stop()
