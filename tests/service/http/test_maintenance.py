"""A drive put in maintenance through the API and taken out of it: no telegram reaches it
at the simulator (an FC drive; a DP slave is left out of the cycle) while the others go
on, writes to it answer 409 in_maintenance, it is shown and exported with its reason,
each switch is audited, and out of maintenance it is polled again (a DP slave
parametrised afresh)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path
from typing import Any

from prometheus_client import generate_latest

from pkwbus.protocol.buses import decode_adr
from pkwbus.protocol.profibus.dp.services import Service as DpService
from pkwbus.sim import Simulator
from tests.master.conftest import until as until_within
from tests.service.assembly.test_ds47_service import TOKEN as DP_TOKEN
from tests.service.assembly.test_ds47_service import service as dp_service
from tests.service.http.conftest import AUTH, fc_drives, service


def heard(sim: Simulator) -> list[int]:
    """The address of every telegram that reaches the simulated line, from now on."""
    seen: list[int] = []
    original = sim.answer

    def answer(telegram: Any, now: float | None = None) -> Any:
        seen.append(decode_adr(sim.protocol, telegram.adr).address)
        return original(telegram, now)

    sim.answer = answer  # type: ignore[method-assign]
    return seen


async def until(check: Callable[[], bool], timeout: float = 30.0) -> None:
    await until_within(check, timeout)  # generous: a loaded machine, a DP slave's start-up


def maintenance_series(registry: Any) -> list[str]:
    text = generate_latest(registry).decode()
    return [line for line in text.splitlines() if line.startswith("pkwbus_drive_maintenance{")]


async def test_an_fc_drive_in_maintenance_gets_no_telegram_and_comes_back(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:2]) as svc:
        url = "/api/v1/drives/fan1/maintenance"
        r = await svc.client.put(url, json={"on": True, "reason": "bearing change"})
        assert r.status_code == 401, "the write token is needed"
        assert "fan1" not in svc.runtime.snapshot.maintenance
        r = await svc.client.put(url, json={"on": True, "reason": "bearing change"}, headers=AUTH)
        assert r.status_code == 200, r.text
        assert r.json()["on"] is True and r.json()["reason"] == "bearing change"
        seen = heard(svc.sim)
        await until(lambda: seen.count(2) >= 20)  # the other drive goes on meanwhile
        assert 1 not in seen, "no telegram, not even a probe, to a drive in maintenance"
        view = {d["name"]: d for d in (await svc.client.get("/api/v1/drives")).json()}
        assert view["fan1"]["maintenance"]["reason"] == "bearing change"
        assert view["fan2"]["maintenance"] is None
        (series,) = maintenance_series(svc.runtime.registry)
        assert 'drive="fan1"' in series and 'reason="bearing change"' in series
        r = await svc.put("fan1", "3-41", {"value": 12.5}, headers=AUTH)
        assert r.status_code == 409 and r.json()["error"]["kind"] == "in_maintenance"
        assert svc.audit_writer.writes(address=1) == []
        r = await svc.client.put(url, json={"on": False}, headers=AUTH)
        assert r.status_code == 200 and r.json()["on"] is False
        await until(lambda: seen.count(1) >= 3)  # polled again at once
        assert maintenance_series(svc.runtime.registry) == []
        assert svc.audit is not None
        rows = [
            (row.parameter, row.outcome, row.new_value, row.detail)
            for row in svc.audit.latest(10)
        ]  # fmt: skip
        assert ("maintenance", "ok", True, "bearing change") in rows
        assert ("maintenance", "ok", False, None) in rows
        assert [r[:3] for r in rows if r[0] == "3-41"] == [("3-41", "not_sent", 12.5)]


async def test_a_dp_slave_in_maintenance_is_left_out_of_the_cycle(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        auth = {"Authorization": f"Bearer {DP_TOKEN}"}
        r = await svc.client.put(
            "/api/v1/drives/pump/maintenance", json={"on": True, "reason": "seal"}, headers=auth
        )
        assert r.status_code == 200, r.text
        since = len(svc.wire.frames)
        await until(lambda: sum(1 for f in svc.wire.frames[since:] if f.da == 8) >= 50)
        assert not [f for f in svc.wire.frames[since:] if f.da == 9], "pump left out"
        assert svc.sample("pkwbus_drive_maintenance", drive="pump", reason="seal") == 1.0
        r = await svc.client.put("/api/v1/drives/pump/maintenance", json={"on": False},
                                 headers=auth)  # fmt: skip
        assert r.status_code == 200
        back = len(svc.wire.frames)
        # Parametrised afresh, then in data exchange and polled again.
        await until(lambda: any(
            f.da == 9 and f.dsap == DpService.SET_PRM for f in svc.wire.frames[back:]
        ))  # fmt: skip
        reads = svc.reads("pump")
        await until(lambda: svc.reads("pump") > reads)
        assert svc.sample("pkwbus_drive_maintenance", drive="pump") is None


async def test_maintenance_true_in_the_configuration_starts_the_drive_so(tmp_path: Path) -> None:
    from pkwbus.service.assembly.build import build_runtime
    from pkwbus.service.config import parse_config
    from pkwbus.sim import SimTiming

    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.001), catalog="danfoss-fc")
    seen = heard(sim)
    end = await sim.serve_tcp("127.0.0.1", 0)
    text = f"""
audit_db: {tmp_path}/audit.sqlite
lines:
  - name: l1
    port: {end.url}
    protocol: fc
    baudrate: 115200
    drives:
      - {{name: fan1, address: 1, catalog: danfoss-fc, maintenance: true,
         poll: [{{parameter: "16-13", every: 50ms}}]}}
      - {{name: fan2, address: 2, catalog: danfoss-fc, poll: [{{parameter: "16-13", every: 50ms}}]}}
"""
    runtime = await build_runtime(parse_config(text, environ={}))
    await runtime.start()
    try:
        await until(lambda: seen.count(2) >= 20)
        assert 1 not in seen
        assert runtime.snapshot.maintenance["fan1"].reason == "configuration"
    finally:
        await runtime.stop()
        await end.close()


class Ended:
    """The reasons of the jobs and polls that ended cancelled, as a line's observer."""

    def __init__(self) -> None:
        self.reasons: list[str] = []

    def on_events(self, events: Any) -> None:
        from pkwbus.master.planning.outcomes import Cancelled
        from pkwbus.master.planning.plan import Finished

        self.reasons += [
            e.outcome.reason
            for e in events
            if isinstance(e, Finished) and isinstance(e.outcome, Cancelled)
        ]


async def test_a_dp_slave_whose_slot_carries_a_job_comes_back_from_maintenance(
    tmp_path: Path,
) -> None:
    """Its PKW slot holds a job when it goes in maintenance (every answer lags a second):
    the job ends there, so that out of maintenance it is polled again, not stuck."""
    from pkwbus.master.planning.planner import IN_MAINTENANCE
    from pkwbus.service.assembly.build import build_runtime
    from pkwbus.service.config import parse_config
    from pkwbus.sim import SimTiming
    from pkwbus.sim.profibus.line import DpSimulator

    sim = DpSimulator([8], timing=SimTiming(response_delay=0.001, lag_seconds=1.0))
    end = await sim.serve_tcp("127.0.0.1", 0)
    text = f"""
audit_db: {tmp_path}/audit.sqlite
lines:
  - name: dp
    port: "{end.url}"
    protocol: profibus
    baudrate: 93750
    slot_time: 50ms
    watchdog: 2s
    alarms: off
    counters: off
    events: off
    describe: off
    drives:
      - {{name: mixer, address: 8, dialect: profidrive, ppo: 1, ident: 0x80B5,
         catalog: siemens-g120, poll: [{{parameter: r0021, every: 100ms}}]}}
"""
    runtime = await build_runtime(parse_config(text, environ={}))
    runner = runtime.runners["dp"]
    await runtime.start()
    try:
        key = ("mixer", "r0021", 0)
        await until(lambda: key in runtime.snapshot.readings)
        planner = runner.planner  # type: ignore[attr-defined]
        await until(lambda: planner.drive("mixer").busy)  # a poll in the slot, lagging
        ended = Ended()
        runner.observers.append(ended)
        runner.maintenance("mixer", True, "test")
        assert not planner.drive("mixer").busy and planner.drive("mixer").active is None
        assert ended.reasons == [IN_MAINTENANCE], "the slot's job ended as in maintenance"
        runner.maintenance("mixer", False)
        before = runtime.snapshot.readings[key].timestamp
        await until(lambda: runtime.snapshot.readings[key].timestamp > before, timeout=30)
    finally:
        await runtime.stop()
        await end.close()


async def test_a_record_write_under_way_never_reaches_a_slave_put_in_maintenance(
    tmp_path: Path,
) -> None:
    """Maintenance begins while a data record 47 write is being carried: its next request
    is never sent, the drive keeps its value, and the audit says it may have gone out."""
    from pkwbus.master.planning.jobs import Job

    async with dp_service(tmp_path) as svc:
        runner: Any = svc.runtime.runners["dp"]
        port = runner.port
        start = port.start
        held: list[int] = []
        before = svc.sim.drives[9].params.number(1121)

        def start_then_hold(request: Any, done: Any) -> Any:
            active = runner.planner.drive("pump").active
            carrying = (
                active is not None and isinstance(active.work, Job)
                and active.work.request.is_write and not active.read_first
            )  # fmt: skip
            if not held and getattr(request, "da", None) == 9 and carrying:
                held.append(len(svc.wire.frames))
                runner.maintenance("pump", True, "seal")
            return start(request, done)

        port.start = start_then_hold
        r = await svc.client.put(
            "/api/v1/drives/pump/parameters/p1121",
            json={"value": 12.15},
            headers={"Authorization": f"Bearer {DP_TOKEN}"},
        )
        assert held, "maintenance began while the write was under way"
        assert r.status_code == 503 and r.json()["error"]["kind"] == "cancelled"
        await asyncio.sleep(0.5)
        assert svc.sim.drives[9].params.number(1121) == before
        (row,) = [e for e in svc.audit.latest(10) if e.parameter == "p1121"]
        assert row.outcome == "cancelled" and "may have been applied" in (row.detail or "")


async def test_a_slave_gone_while_in_maintenance_is_down_when_taken_back(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        runner: Any = svc.runtime.runners["dp"]
        runner.maintenance("fan", True, "motor swap")
        assert svc.runtime.snapshot.slaves["fan"].state.value == "offline"  # sent nothing
        svc.sim.kill(10)  # the fitter took it away
        runner.maintenance("fan", False)
        await until(lambda: svc.sample("pkwbus_drive_up", drive="fan") == 0.0)
        svc.sim.revive(10)  # back on the bus: in data exchange, up again
        await until(lambda: svc.sample("pkwbus_drive_up", drive="fan") == 1.0)


async def test_a_malformed_switch_is_refused_audited_and_changes_nothing(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:1]) as svc:
        url = "/api/v1/drives/fan1/maintenance"
        r = await svc.client.put(url, json={"on": "yes"})
        assert r.status_code == 401, "no token: that is the answer"
        r = await svc.client.put(url, json={"on": "yes"}, headers=AUTH)
        assert r.status_code == 422 and r.json()["error"]["kind"] == "invalid_request"
        # A reason is one line of text: a newline or another control character would start
        # a line of its own in the audit table and the log, as if another entry.
        for reason in (
            "bearing\n2026-11-29 ok write fan1 3-41",
            "tab\there",
            "bell\x07",
            "next\x85line",
            "line\u2028separator",
            "csi\x9b2J",
            "rtl\u202eoverride",
        ):
            r = await svc.client.put(url, json={"on": True, "reason": reason}, headers=AUTH)
            assert r.status_code == 422, (reason, r.text)
            assert r.json()["error"]["kind"] == "invalid_request"
        r = await svc.client.put("/api/v1/drives/nobody/maintenance", json={"on": True},
                                 headers=AUTH)  # fmt: skip
        assert r.status_code == 404
        assert svc.runtime.snapshot.maintenance == {}
        assert svc.audit is not None
        rows = [(row.drive, row.parameter, row.outcome) for row in svc.audit.latest(10)]
        assert ("fan1", "maintenance", "invalid") in rows
        assert ("nobody", "maintenance", "invalid") in rows


async def test_a_write_queued_when_maintenance_begins_is_answered_in_maintenance(
    tmp_path: Path,
) -> None:
    """A write waits behind another of its drive when the drive goes in maintenance: it is
    never sent, and is answered and audited as a write to a drive in maintenance is (README
    "A drive in maintenance": 409 in_maintenance, audited not_sent)."""
    from pkwbus.sim import SimTiming

    async with service(tmp_path, fc=fc_drives()[:1], timing=SimTiming(response_delay=0.15),
                       line_timeout=1.0) as svc:  # fmt: skip
        before = svc.sim.drives[1].value(342)
        first = asyncio.create_task(svc.put("fan1", "3-41", {"value": 11}))
        queued = asyncio.create_task(svc.put("fan1", "3-42", {"value": 12}))
        from pkwbus.master.planning.jobs import Job

        d = svc.runtime.runners["line_fc"].planner.drive("fan1")  # type: ignore[attr-defined]
        await until(  # the first on the wire, the second queued behind it
            lambda: d.active is not None and isinstance(d.active.work, Job) and len(d.writes) == 1
        )
        r = await svc.client.put("/api/v1/drives/fan1/maintenance",
                                 json={"on": True, "reason": "bearing"}, headers=AUTH)  # fmt: skip
        assert r.status_code == 200
        await first
        answer = await queued
        assert (answer.status_code, answer.json()["error"]["kind"]) == (409, "in_maintenance")
        assert svc.audit is not None
        (row,) = [e for e in svc.audit.latest(10) if e.parameter == "3-42"]
        assert row.outcome == "not_sent", row
        assert svc.audit_writer.writes(1, 342) == [] and svc.sim.drives[1].value(342) == before


async def test_taken_out_ends_a_maintenance_shown_that_the_line_no_longer_holds(
    tmp_path: Path,
) -> None:
    """``{"on": false}`` ends what is shown even where the line's planner had the drive out
    already (a maintenance told by a line a reload replaced): writes go through again."""
    from pkwbus.master.snapshot import Maintained

    async with service(tmp_path, fc=fc_drives()[:1]) as svc:
        svc.runtime.snapshot.maintenance["fan1"] = Maintained("told by a line gone", 1.0)
        assert (await svc.put("fan1", "3-41", {"value": 11})).status_code == 409
        r = await svc.client.put("/api/v1/drives/fan1/maintenance", json={"on": False},
                                 headers=AUTH)  # fmt: skip
        assert r.status_code == 200 and r.json()["on"] is False
        assert "fan1" not in svc.runtime.snapshot.maintenance
        assert not maintenance_series(svc.runtime.registry)
        assert (await svc.put("fan1", "3-41", {"value": 11})).status_code == 200
