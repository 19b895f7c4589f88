"""The service over simulated PROFIBUS DP slaves on TCP: values, writes, restarts, dead
and locked slaves, and its error counters against the faults the simulator injected.

Every test also checks the wire: each PPO-write pkwbus sent had a control word
of 0 (bit 10 clear), so the service never took control of a drive.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import AsyncIterator, Callable, Iterable, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import httpx
import pytest
from prometheus_client import generate_latest

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.events import Event, Exchanged
from pkwbus.master.planning.answers import ExchangeResult, Failure, PkwAnswer, Reply
from pkwbus.master.planning.jobs import JobKind
from pkwbus.master.planning.outcomes import Rejected
from pkwbus.master.planning.plan import HealthChanged
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.runner import LineRunner
from pkwbus.master.wires.profibus.wire import CycleWire
from pkwbus.protocol import pkw, pzd
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp.services import Service
from pkwbus.protocol.profibus.dp.slave import RestartReason, SlaveState
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.audit.log import AuditLog
from pkwbus.service.config import parse_config
from pkwbus.service.http.api import create_app
from pkwbus.service.metrics.instrumentation import ERROR_KINDS
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.drives.params import FaultNumbers
from pkwbus.sim.profibus.line import DpFaults, DpSimulator
from pkwbus.sim.serving.ends import TcpEnd
from tests.master.wires.profibus.frame_log import FrameLog, log_frames

TOKEN = "s3cret-Write-Token-0123456789"
ADDRESSES = (8, 9, 10)
NAMES = {8: "mixer", 9: "pump", 10: "fan"}


def config_text(url: str, audit: Path, slot_time: str = "20ms") -> str:
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
    slot_time: {slot_time}
    watchdog: 2s
    alarms: off  # the tests count the PKW jobs of the polls they configure
    counters: off
    drives:
{drives}
"""


@dataclass
class DpService:
    sim: DpSimulator
    wire: FrameLog
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
async def dp_service(
    tmp_path: Path,
    faults: DpFaults | None = None,
    slot_time: str = "20ms",
    watch: Callable[[DpSimulator], None] | None = None,
) -> AsyncIterator[DpService]:
    """The service over simulated slaves; ``watch`` sees the simulator before it serves."""
    async with AsyncExitStack() as stack:
        sim = DpSimulator(
            ADDRESSES,
            dialect="danfoss-pcv",
            timing=SimTiming(response_delay=0.001),
            seed=5,
            faults=faults,
        )
        wire = log_frames(sim)
        if watch is not None:
            watch(sim)
        end = await sim.serve_tcp("127.0.0.1", 0)
        env = {"TEST_TOKEN": TOKEN}
        text = config_text(end.url, tmp_path / "audit.sqlite", slot_time)
        config = parse_config(text, environ=env)
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


async def test_the_main_actual_value_of_every_cycle_is_exported_as_percent(
    tmp_path: Path,
) -> None:
    async with dp_service(tmp_path) as svc:
        for address, hz in zip(ADDRESSES, (12.5, 30.0, 47.0), strict=True):
            model = svc.sim.drives[address].model
            model.setpoint = model.frequency = hz  # a different value for each slave
        mav = "pkwbus_drive_main_actual_percent"
        await until(lambda: len({svc.sample(mav, drive=n) for n in NAMES.values()}) == 3)
        # Stopped, every answer sent is accounted for: the exported value is the one of
        # each slave's latest PPO-read, which the simulated drive still holds.
        await svc.runtime.stop()
        values = {a: svc.sample(mav, drive=n) for a, n in NAMES.items()}
        assert len(set(values.values())) == len(ADDRESSES)
        for address in ADDRESSES:
            assert values[address] == pzd.ref_to_percent(svc.sim.drives[address].mav)


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


async def test_a_slave_dead_from_the_start_is_shown_down_until_it_answers(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A slave that never reached data exchange and answers none of a request's repeats is
    down (pkwbus_drive_up 0: PkwbusDriveDown), not up by default, and the log says it does
    not answer; the others are up."""
    caplog.set_level(logging.WARNING, logger="pkwbus.master.runner")
    sim = DpSimulator(ADDRESSES, dialect="danfoss-pcv", timing=SimTiming(response_delay=0.001),
                      seed=5, faults=DpFaults(dead=frozenset({10})))  # fmt: skip
    end = await sim.serve_tcp("127.0.0.1", 0)
    text = config_text(end.url, tmp_path / "audit.sqlite", "20ms")
    runtime = await build_runtime(parse_config(text, environ={"TEST_TOKEN": TOKEN}))
    await runtime.start()

    def up(name: str) -> bool | None:
        state = runtime.snapshot.drives.get(name)
        return None if state is None else state.up

    try:
        await until(lambda: up("fan") is False)
        await until(lambda: all(runtime.snapshot.readings.get((n, "16-13", 0)) for n in
                                ("mixer", "pump")))  # fmt: skip
        said = "drive fan is down: does not answer"
        await until(lambda: any(r.getMessage().startswith(said) for r in caplog.records))
        assert up("mixer") is not False and up("pump") is not False
        sim.revive(10)
        await until(lambda: up("fan") is True)
    finally:
        await runtime.stop()
        await end.close()


async def test_slaves_that_never_reach_data_exchange_are_down_and_the_api_says_why(
    tmp_path: Path,
) -> None:
    """A slave owned by another master from the start, and one that refuses its parameters
    (another ident number), never reach data exchange: they are down from the start
    (pkwbus_drive_up 0, overview "down"), never shown up, and a read or write of theirs
    answers 503 with their state and the cause their diagnosis gives, not "try again in a
    few seconds"."""
    sim = DpSimulator(ADDRESSES, dialect="danfoss-pcv", timing=SimTiming(response_delay=0.001),
                      seed=5)  # fmt: skip
    sim.lock(10, 1)
    sim.slaves[9].ident = 0x1234
    end = await sim.serve_tcp("127.0.0.1", 0)
    text = config_text(end.url, tmp_path / "audit.sqlite", "20ms")
    config = parse_config(text, environ={"TEST_TOKEN": TOKEN})
    runtime = await build_runtime(config)
    shown_up: set[str] = set()

    class Watch:
        def on_events(self, events: Sequence[Event]) -> None:
            shown_up.update(e.drive for e in events if isinstance(e, HealthChanged) and e.up)

    runtime.runners["dp"].observers.append(Watch())  # type: ignore[attr-defined]
    await runtime.start()
    audit = AuditLog(config.audit_db)
    app = create_app(runtime, audit=audit, write_token=config.write_token({"TEST_TOKEN": TOKEN}))
    client = httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t")
    snapshot = runtime.snapshot

    def flags(name: str) -> frozenset[str]:
        live = snapshot.slaves.get(name)
        return live.flags if live is not None else frozenset()

    try:
        await until(lambda: runtime.snapshot.readings.get(("mixer", "16-13", 0)) is not None)
        await until(lambda: "prm_fault" in flags("pump"))
        await until(lambda: snapshot.slaves["fan"].state is SlaveState.LOCKED)
        metrics = generate_latest(runtime.registry).decode()
        for name, up in (("mixer", 1), ("pump", 0), ("fan", 0)):
            assert f'pkwbus_drive_up{{drive="{name}",line="dp"}} {up}.0' in metrics
        overview = (await client.get("/api/v1/drives?view=overview")).json()
        assert {d["name"]: d["state"] for d in overview} == {
            "mixer": "up", "pump": "down", "fan": "down"
        }  # fmt: skip
        assert shown_up == {"mixer"}  # the others never, not even at the start
        fan = await client.get("/api/v1/drives/fan/parameters/16-13")
        pump = await client.put(
            "/api/v1/drives/pump/parameters/3-41", json={"value": 12.5},
            headers={"Authorization": f"Bearer {TOKEN}"},
        )  # fmt: skip
        assert fan.status_code == pump.status_code == 503
        said = {n: r.json()["error"]["message"] for n, r in (("fan", fan), ("pump", pump))}
        assert said["fan"].startswith(
            "fan is down: not in data exchange (locked): slave 10 is owned by master 1"
        )
        assert said["pump"].startswith("pump is down: not in data exchange (")
        assert "slave 9 refuses its parameters (Prm_Fault)" in said["pump"]
        assert all("few seconds" not in m for m in said.values())
        assert sim.drives[9].params.value(341) != 1250  # nothing was sent
    finally:
        await client.aclose()
        audit.close()
        await runtime.stop()
        await end.close()


@dataclass
class Window:
    """What went on the wire over some master cycles."""

    cycles: int
    exchanges: Counter[int]  # Data_Exchange requests, by slave
    requests: Counter[int]  # every request, by slave

    def per_cycle(self, address: int) -> float:
        return self.exchanges[address] / self.cycles


async def window(svc: DpService, cycles: int) -> Window:
    """The wire over the next ``cycles`` cycles of the DP master: counts, not a duration."""
    runner = svc.runtime.runners["dp"]
    assert isinstance(runner, LineRunner) and isinstance(runner.wire, CycleWire)
    master = runner.wire.cycle
    first_cycle, first_frame = master.cycles, len(svc.wire.frames)
    await until(lambda: master.cycles >= first_cycle + cycles)
    frames = svc.wire.frames[first_frame:]
    return Window(
        master.cycles - first_cycle,
        Counter(f.da for f in frames if f.dsap is None and f.data),
        Counter(f.da for f in frames if f.da != fdl.BROADCAST),
    )


async def test_a_slave_owned_by_another_master_is_locked_and_costs_the_others_nothing(
    tmp_path: Path,
) -> None:
    other_master = 1
    async with dp_service(tmp_path) as svc:
        baseline = await window(svc, 300)
        assert all(baseline.exchanges[a] > 0 for a in ADDRESSES)
        svc.sim.lock(10, other_master)
        await until(lambda: svc.state("fan") is SlaveState.LOCKED)
        assert svc.sample("pkwbus_dp_slave_state", drive="fan", state="locked") == 1
        assert svc.sample("pkwbus_drive_up", drive="fan") == 0
        sent_before_lock = len(svc.wire.frames)
        locked = await window(svc, 300)
        # Per master cycle the others get their Data_Exchange as often as before, and the
        # locked slave, probed at back-off, takes under 5 % of the line's requests: the
        # others have at least 95 % of the line they would have without it.
        for address in (8, 9):
            assert locked.per_cycle(address) >= 0.95 * baseline.per_cycle(address)
        assert locked.requests[10] <= 0.05 * locked.requests.total()
        assert baseline.requests[10] >= baseline.cycles - 1  # before: once every cycle
        assert all(
            svc.sample("pkwbus_jobs_total", drive=n, kind="read", outcome=o) is None
            for n in ("mixer", "pump")
            for o in ("timeout", "cancelled")
        )

        # Locked: pkwbus reads its diagnosis at back-off (probes after 1 s, then 2 s more),
        # never parametrises it or sends it data.
        def to_fan() -> list[fdl.DataFrame]:
            return [f for f in svc.wire.frames[sent_before_lock:] if f.da == 10]

        await until(lambda: len(to_fan()) >= 2)
        assert all(f.dsap == Service.SLAVE_DIAG for f in to_fan())
        assert svc.sim.slaves[10].owner == other_master
        # The other master lets go: the slave is parametrised and exchanges data again.
        svc.sim.release(10)
        await until(lambda: svc.state("fan") is SlaveState.DATA_EXCHANGE)
        reads = svc.reads("fan")
        await until(lambda: svc.reads("fan") >= reads + 2)
        assert svc.sample("pkwbus_drive_up", drive="fan") == 1
        runner = svc.runtime.runners["dp"]
        assert isinstance(runner, LineRunner) and isinstance(runner.wire, CycleWire)
        assert svc.sim.slaves[10].owner == runner.port.master
        # Control word bit 10 clear in every PPO-write to every slave (also checked at exit).
        for address in ADDRESSES:
            outputs = [f for f in svc.wire.data_exchanges() if f.da == address]
            assert outputs
            assert all(int.from_bytes(f.data[8:10], "big") == pzd.MONITORING_CTW for f in outputs)


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


# ------------------------------------------------------------ faults against the simulator's


def counts(
    svc: DpService, name: str, label: str, values: Iterable[str], drive: str
) -> Counter[str]:
    out: Counter[str] = Counter()
    for value in values:
        out[value] = int(svc.sample(name, drive=drive, **{label: value}) or 0)
    return out


def telegram_errors(svc: DpService, drive: str) -> Counter[str]:
    return counts(svc, "pkwbus_telegram_errors_total", "kind", ERROR_KINDS, drive)


def restarts(svc: DpService, drive: str) -> Counter[str]:
    return counts(svc, "pkwbus_dp_restarts_total", "reason", list(RestartReason), drive)


async def test_telegram_errors_and_pkw_faults_are_what_the_simulator_injected(
    tmp_path: Path,
) -> None:
    """One injected fault, one error of its kind on its slave: a dropped answer is a
    timeout, a wrong FCS a checksum error; noise before a frame is skipped (no error).
    The simulator answers within about a millisecond, well inside the slot time: only a
    dropped answer misses it (a slot time of 200 ms: a busy test machine that holds the
    loop or the simulator for 50 ms would have made a timeout of its own)."""
    faults = DpFaults(drop=0.03, corrupt=0.03, garbage=0.03)
    async with dp_service(tmp_path, faults, slot_time="200ms") as svc:
        injected = svc.sim.stats.injected
        await until(lambda: all(injected[k] >= 10 for k in ("drop", "corrupt", "garbage")))
        # A PKW fault the drive answers: a write to a read-only parameter (16-13).
        result = await svc.runtime.submit(
            "mixer",
            pkw.write(svc.sim.dialect, 1613, 1, pkw.Width.DWORD),
            JobKind.WRITE,
            ParameterDescription(),
        )
        await svc.runtime.stop()  # every exchange accounted for on both sides
        for address, name in NAMES.items():
            did = svc.sim.stats.drive_injected[address]
            assert telegram_errors(svc, name) == Counter(
                timeout=did["drop"], checksum=did["corrupt"]
            ), (name, did)
            assert restarts(svc, name).total() == 0
    fault = FaultNumbers.of(svc.sim.dialect).read_only
    text = dict(pkw.rejections(svc.sim.dialect))[fault]
    assert isinstance(result.outcome, Rejected) and result.outcome.fault == fault
    assert result.outcome.short == text
    assert (
        svc.sample("pkwbus_pkw_faults_total", drive="mixer", fault_code=str(fault), fault=text) == 1
    )
    assert all(
        svc.sample("pkwbus_pkw_faults_total", drive=n, fault_code=str(fault)) == 0
        for n in ("pump", "fan")
    )


async def test_restarts_are_the_simulators_rs_answers_and_power_cycles(tmp_path: Path) -> None:
    """An injected RS answer is one restart (reason rs). A power cycle (``restart``) is seen
    as the slave's next answer says: on a Data_Exchange the slave answers RS (one restart,
    rs); on Chk_Cfg or the diagnosis after it, its diagnosis asks for parameters
    (prm_required, at most one for such power cycles: two before that diagnosis make one);
    on the first diagnosis or Set_Prm of a start-up it goes unnoticed, as the start-up
    parametrises it anyway."""
    previous: dict[int, int | None] = {}
    hits: dict[int, Counter[str]] = {a: Counter() for a in ADDRESSES}

    def watch(sim: DpSimulator) -> None:
        """Which request each injected power cycle hit."""
        answer = sim.answer

        def watched(frame: object, now: float | None = None) -> Answer | None:
            before = sim.stats.injected["restart"]
            result = answer(frame, now)
            if isinstance(frame, fdl.DataFrame) and frame.da in hits:
                if sim.stats.injected["restart"] > before:
                    after_cfg = previous.get(frame.da) == Service.CHK_CFG
                    if frame.dsap is None:
                        hits[frame.da]["data_exchange"] += 1
                    elif frame.dsap == Service.CHK_CFG or after_cfg:
                        hits[frame.da]["prm_required"] += 1
                    else:
                        hits[frame.da]["unnoticed"] += 1
                previous[frame.da] = frame.dsap
            return result

        sim.answer = watched  # type: ignore[method-assign]

    faults = DpFaults(rs=0.02, restart=0.02)
    async with dp_service(tmp_path, faults, slot_time="50ms", watch=watch) as svc:
        injected = svc.sim.stats.injected
        await until(lambda: all(injected[k] >= 10 for k in ("rs", "restart")))
        await svc.runtime.stop()
        for address, name in NAMES.items():
            did, hit, seen = (
                svc.sim.stats.drive_injected[address],
                hits[address],
                restarts(svc, name),
            )
            assert sum(hit.values()) == did["restart"]
            assert seen["rs"] == did["rs"] + hit["data_exchange"], (name, did, hit, seen)
            assert seen["prm_required"] <= hit["prm_required"], (name, hit, seen)
            assert seen["watchdog"] == seen["diag"] == 0
            assert telegram_errors(svc, name).total() == 0


async def test_late_answers_are_timeouts_of_their_own_slave_only(tmp_path: Path) -> None:
    """Answers of the fan come after the slot time (the other slaves answer in time).

    Each late answer is a timeout of the fan, never an error of another slave (its
    source address is not theirs). Not exactly one each: a late answer that arrives while
    the fan's next request is out is taken as that request's answer (the fan's, with
    older data), and when that request's own answer was late too, that one times out no
    request. So ``1 <= timeouts <= late``; an error other than a timeout can only come
    of such an older answer (``unexpected <= late``).
    """

    def watch(sim: DpSimulator) -> None:
        answer = sim.answer
        faults = sim.faults

        def fan_only(frame: object, now: float | None = None) -> Answer | None:
            is_fan = isinstance(frame, fdl.DataFrame) and frame.da == 10
            sim.faults = faults if is_fan else DpFaults()
            try:
                return answer(frame, now)
            finally:
                sim.faults = faults

        sim.answer = fan_only  # type: ignore[method-assign]

    # A slot time of 200 ms: the other slaves' answers, in time, must not miss it because a
    # loaded machine held the simulator's process (at 50 ms it failed so once, load 4.8).
    faults = DpFaults(late=0.05, late_seconds=0.5)
    async with dp_service(tmp_path, faults, slot_time="200ms", watch=watch) as svc:
        await until(lambda: svc.sim.stats.injected["late"] >= 10)
        await svc.runtime.stop()
        late = svc.sim.stats.drive_injected[10]["late"]
        assert svc.sim.stats.injected.total() == late
        fan = telegram_errors(svc, "fan")
        assert 1 <= fan["timeout"] <= late
        assert fan["unexpected"] <= late
        assert fan.total() == fan["timeout"] + fan["unexpected"]
        for name in ("mixer", "pump"):
            assert telegram_errors(svc, name).total() == 0, name
            assert restarts(svc, name).total() == 0, name


async def test_the_line_is_busy_for_as_long_as_each_exchange_held_it(tmp_path: Path) -> None:
    """Each exchange adds the time it held the line to the line's busy time, as on FC and
    USS lines: a request without answer held it for the whole slot time at least; an
    answer's duration runs from the request written, the idle time before it left out."""
    slot = 0.2
    seen: list[Exchanged] = []
    async with dp_service(tmp_path, slot_time=f"{slot * 1000:.0f}ms") as svc:
        runner = svc.runtime.runners["dp"]
        assert isinstance(runner, LineRunner) and isinstance(runner.wire, CycleWire)

        class Tap:
            def on_events(self, events: Sequence[Event]) -> None:
                seen.extend(e for e in events if isinstance(e, Exchanged))

        runner.observers.append(Tap())
        svc.sim.kill(10)
        await until(lambda: sum(e.error is not None for e in seen) >= 3)
        await svc.runtime.stop()
    timeouts = [e.busy for e in seen if e.error is not None]
    assert all(busy >= slot for busy in timeouts), timeouts
    replies = [e for e in seen if e.error is None]
    # busy: from the start, the line's idle time before the request included; the answer's
    # duration: from the request written, as on FC and USS lines
    assert replies and all(e.answered is not None and e.busy > e.answered > 0 for e in replies)


async def test_every_request_a_slave_received_is_one_telegram_of_the_line(tmp_path: Path) -> None:
    """The start-up requests (diagnosis, Set_Prm, Chk_Cfg) held the line as Data_Exchange
    does: each counts in pkwbus_telegrams_total and in the busy time, at start and when a
    restarted slave is parametrised again."""
    async with dp_service(tmp_path) as svc:
        busy_at_start = svc.sample("pkwbus_line_busy_seconds_total", line="dp") or 0.0
        svc.sim.restart(9)
        await until(lambda: restarts(svc, "pump").total() >= 1)
        reads = svc.reads("pump")
        await until(lambda: svc.reads("pump") >= reads + 2)
        await svc.runtime.stop()  # every exchange accounted for on both sides
        for address, name in NAMES.items():
            received = svc.sim.stats.drives[address]["requests"]
            assert svc.sample("pkwbus_telegrams_total", drive=name) == received, name
        assert (svc.sample("pkwbus_line_busy_seconds_total", line="dp") or 0.0) > busy_at_start


async def test_a_job_answer_reaches_the_planner_decoded_once_with_its_exchange(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every PPO-read that answers a job goes to the planner as it came, with the time its
    exchange took, for the job's transaction to judge (the one rule of every bus): the
    wire builds no answer, and the job's carrier takes what the slot decoded of those
    bytes, never decoding them again. The PPO-read's status word goes out with every
    cycle's Inputs, once."""
    decoded: list[bytes] = []
    decode = ppo.decode_ppo_read

    def counted(kind: ppo.PpoType, dia: Any, data: bytes, profile: Any = None) -> ppo.PpoRead:
        decoded.append(data)
        return decode(kind, dia, data, profile)

    monkeypatch.setattr(ppo, "decode_ppo_read", counted)
    async with dp_service(tmp_path) as svc:
        (runner,) = svc.runtime.runners.values()
        assert isinstance(runner, LineRunner) and isinstance(runner.wire, CycleWire)
        seen: list[ExchangeResult] = []
        answers: list[PkwAnswer] = []
        planner = runner.planner
        exchanged = planner.exchanged

        def spy(send: object, result: ExchangeResult, now: float) -> None:
            seen.append(result)
            tx = planner.active(send.drive)  # type: ignore[attr-defined]
            if isinstance(tx, PkwTransaction) and isinstance(result, Reply):
                answers.append(tx.decode(result.data, result.duration))
            exchanged(send, result, now)  # type: ignore[arg-type]

        planner.exchanged = spy  # type: ignore[method-assign]
        await until(lambda: len(seen) >= 6)
    replies = [r for r in seen if isinstance(r, Reply)]
    assert replies and all(isinstance(r, Reply | Failure) for r in seen)
    for reply in replies:
        assert reply.duration > 0
        # Decoded once, by the slot: the carrier took the slot's reading of these bytes.
        assert sum(data is reply.data for data in decoded) == 1
    for answer in answers:
        assert answer.status_word is None  # told by the cycle's Inputs, not twice
        assert isinstance(answer.response, pkw.PkwResponse)
    assert svc.sample("pkwbus_drive_status_word", drive="mixer") is not None
