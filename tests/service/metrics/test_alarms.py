"""Alarms in words: a simulated drive trips, its alarm word is shown with the vendor's text
on the page's API and as pkwbus_drive_alarm, and goes when the drive is reset."""

from __future__ import annotations

import logging

import httpx
import pytest
from prometheus_client import CollectorRegistry, generate_latest

from pkwbus.catalog.alarms import CodeTable, alarm_table
from pkwbus.master.alarms import said, tells_alarms
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.outcomes import Answered
from pkwbus.master.planning.plan import DriveSpec, Finished, PollSpec
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.service.http.api import create_app
from pkwbus.service.metrics.alarms import AlarmCollector
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.drives.model import ModelConfig
from tests.master.conftest import until
from tests.service.assembly.test_service_e2e import fc_line, running, sample

DRIVES = """
      - name: press
        address: 1
        catalog: danfoss-fc
        poll: [{parameter: "16-90", every: 100ms}, {parameter: "16-13", every: 100ms}]
      - name: saw
        address: 2
        catalog: danfoss-fc
        poll: [{parameter: "16-90", every: 100ms}]
"""


def test_the_danfoss_alarm_word_against_its_table() -> None:
    # Danfoss VLT EtherNet/IP MCA 121 manual, the table of 16-90: 00000004 Earth fault,
    # 00000040 Over current; bit 13 is not explained there: its code alone.
    table = alarm_table("danfoss-fc")
    assert table is not None
    word = table.decoder(1690)
    assert word is not None
    alarms = word.decode(0x00000004 | 0x00000040 | 0x00002000)
    assert [(a.code, a.text) for a in alarms] == [
        ("16-90 bit 2", "Earth fault"), ("16-90 bit 6", "Over current"), ("16-90 bit 13", "")
    ]  # fmt: skip
    assert word.decode(0) == ()
    assert table.decoder(1613) is None  # not an alarm parameter


def _writer(drive: str, catalog: str, *parameters: tuple[int, str]) -> SnapshotWriter:
    """A line's snapshot writer with ``drive`` polling ``parameters`` (PNU, name), its alarm
    parameters as the drive's catalog's alarm table tells them (as plan_drive gives them)."""
    table = alarm_table(catalog)
    assert table is not None
    target = DriveTarget.create("fc", 1)
    polls = tuple(PollSpec(name, 0, pkw.read(target.dialect, pnu), 1.0) for pnu, name in parameters)
    alarms = tuple(
        (name, 0, d) for pnu, name in parameters
        if (d := table.decoder(pnu)) is not None and tells_alarms(d)
    )  # fmt: skip
    spec = DriveSpec(drive, carrier_for(target), polls, alarms=alarms)
    return SnapshotWriter("line_fc", [spec], Snapshot())


def _landed(writer: SnapshotWriter, drive: str, parameter: str, value: int, at: float) -> None:
    """A poll of ``parameter`` answered with ``value`` at ``at`` (wall clock)."""
    poll = next(p for p in writer._polls[drive] if p.parameter == parameter)
    answer = pkw.ValueResponse(1, poll.request.pnu, 0, value, pkw.Width.WORD)
    writer.apply([Finished(drive, poll, Answered(answer))], at)


def test_the_danfoss_extended_status_word_is_told_bit_by_bit_and_never_an_alarm() -> None:
    # 16-94 Ext. Status Word (Danfoss BACnet OI MG.14.C1.02, 7.1: one bit each); no
    # reachable document words its bits: each set bit is its code alone.
    table = alarm_table("danfoss-fc")
    assert table is not None
    word = table.decoder(1694)
    assert word is not None and word.kind == "status" and not word.polled
    alarms = word.decode(0x00000001 | 0x00000008)
    assert [(a.code, a.text, a.kind) for a in alarms] == [
        ("16-94 bit 0", "", "status"), ("16-94 bit 3", "", "status")
    ]  # fmt: skip
    # Polled, its value is told in bits on the page; no alarm comes of it.
    assert said(word, 0x9) == "16-94 bit 0; 16-94 bit 3"
    assert not tells_alarms(word)
    writer = _writer("press", "danfoss-fc", (1694, "16-94"))
    _landed(writer, "press", "16-94", 0x9, 1000.0)
    assert writer.snapshot.readings[("press", "16-94", 0)].value == 0x9
    assert writer.snapshot.alarms == {}
    registry = CollectorRegistry()
    registry.register(AlarmCollector(writer.snapshot, {"press": "line_fc"}))
    assert "pkwbus_drive_alarm{" not in generate_latest(registry).decode()


def test_the_writer_keeps_each_alarm_from_the_reading_that_first_showed_it(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Danfoss 16-90: bits 2 (Earth fault) and 6 (Over current) come one after the other;
    the first keeps its time while the word changes, each is told once as it comes and as
    it goes, and the series follow the read model."""
    caplog.set_level(logging.INFO, logger="pkwbus.master.runner")
    writer = _writer("press", "danfoss-fc", (1690, "16-90"), (1613, "16-13"))
    snap = writer.snapshot
    registry = CollectorRegistry()
    registry.register(AlarmCollector(snap, {"press": "line_fc"}))
    _landed(writer, "press", "16-90", 0, 1000.0)
    assert "press" not in snap.alarms
    _landed(writer, "press", "16-90", 0x4, 1001.0)
    _landed(writer, "press", "16-90", 0x4, 1002.0)  # the same word: nothing told again
    _landed(writer, "press", "16-90", 0x44, 1003.0)
    shown = [(a.alarm.code, a.alarm.text, a.since) for a in snap.alarms["press"]]
    assert shown == [
        ("16-90 bit 2", "Earth fault", 1001.0),
        ("16-90 bit 6", "Over current", 1003.0),
    ]
    came = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert came == ["drive press: alarm 16-90 bit 2 Earth fault (16-90)",
                    "drive press: alarm 16-90 bit 6 Over current (16-90)"]  # fmt: skip
    text = generate_latest(registry).decode()
    assert (
        'code="16-90 bit 6",drive="press",kind="alarm",line="line_fc",text="Over current"} 1.0'
        in text
    )
    _landed(writer, "press", "16-13", 0x4, 1004.0)  # no alarm parameter: nothing of alarms
    _landed(writer, "press", "16-90", 0x40, 1005.0)
    assert [(a.alarm.code, a.since) for a in snap.alarms["press"]] == [("16-90 bit 6", 1003.0)]
    gone = [r.getMessage() for r in caplog.records if r.levelno == logging.INFO]
    assert gone == ["drive press: alarm 16-90 bit 2 Earth fault is gone"]
    assert 'code="16-90 bit 2"' not in generate_latest(registry).decode()
    # Its polls changed (a reload): the alarm word no longer polled, what it showed goes.
    target = DriveTarget.create("fc", 1)
    spec = DriveSpec("press", carrier_for(target), writer._polls["press"][1:])
    writer.update_polls(spec, spec.polls)
    assert "press" not in snap.alarms
    assert "pkwbus_drive_alarm{" not in generate_latest(registry).decode()


def test_one_drive_s_alarm_polls_changed_or_gone_leave_the_other_drives_alarms() -> None:
    """Two drives on a line, each polling Danfoss 16-90: one drive's alarm word no longer
    polled, then the drive removed, and the other's alarm stays, its word still decoded."""
    table = alarm_table("danfoss-fc")
    assert table is not None
    decoder = table.decoder(1690)
    assert decoder is not None
    specs = []
    for address, drive in enumerate(("press", "saw"), start=1):
        target = DriveTarget.create("fc", address)
        polls = (
            PollSpec("16-90", 0, pkw.read(target.dialect, 1690), 1.0),
            PollSpec("16-13", 0, pkw.read(target.dialect, 1613), 1.0),
        )
        specs.append(DriveSpec(drive, carrier_for(target), polls, alarms=(("16-90", 0, decoder),)))
    writer = SnapshotWriter("line_fc", specs, Snapshot())
    snap = writer.snapshot
    _landed(writer, "press", "16-90", 0x4, 1000.0)
    _landed(writer, "saw", "16-90", 0x40, 1001.0)
    press = writer._polls["press"]
    spec = DriveSpec("press", specs[0].carrier, press[1:])  # press: 16-90 no longer polled
    writer.update_polls(spec, spec.polls)
    assert "press" not in snap.alarms
    assert [(a.alarm.code, a.since) for a in snap.alarms["saw"]] == [("16-90 bit 6", 1001.0)]
    _landed(writer, "saw", "16-90", 0x44, 1002.0)  # saw's word still decoded
    assert [a.alarm.code for a in snap.alarms["saw"]] == ["16-90 bit 6", "16-90 bit 2"]
    writer.update_polls(specs[0], press)  # press polls its word again: decoded again
    _landed(writer, "press", "16-90", 0x4, 1003.0)
    assert [(a.alarm.code, a.since) for a in snap.alarms["press"]] == [("16-90 bit 2", 1003.0)]
    writer.remove_drive("press")
    assert set(snap.alarms) == {"saw"}
    _landed(writer, "saw", "16-90", 0x0, 1004.0)
    assert snap.alarms == {}


def test_a_drive_gone_takes_its_alarms_with_it() -> None:
    writer = _writer("press", "danfoss-fc", (1690, "16-90"))
    _landed(writer, "press", "16-90", 0x4, 1000.0)
    assert [a.alarm.code for a in writer.snapshot.alarms["press"]] == ["16-90 bit 2"]
    writer.remove_drive("press")
    assert writer.snapshot.alarms == {}


async def test_a_trip_is_shown_in_words_and_goes_with_the_reset(
    caplog: pytest.LogCaptureFixture,
) -> None:
    calm = ModelConfig(trip_rate=0.0, warning_rate=0.0, trip_reset_seconds=0.0)
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.001), catalog="danfoss-fc",
                    model=calm)  # fmt: skip
    server = await sim.serve_tcp("127.0.0.1", 0)
    caplog.set_level(logging.INFO, logger="pkwbus.master.runner")
    try:
        async with running(f"lines:{fc_line('l1', server.url, DRIVES)}") as runtime:
            app = create_app(runtime, audit=None, write_token=None)
            async with httpx.AsyncClient(
                transport=httpx.ASGITransport(app=app), base_url="http://t"
            ) as client:
                await until(lambda: sample(runtime, "pkwbus_parameter_value", drive="press",
                                           parameter="16-90") == 0)  # fmt: skip
                assert sample(runtime, "pkwbus_drive_alarm", drive="press") is None
                sim.drives[1].model.trip(14, 2)  # earth fault, bit 2 of 16-90
                labels = {"drive": "press", "code": "16-90 bit 2", "text": "Earth fault",
                          "kind": "alarm", "line": "l1"}  # fmt: skip
                await until(lambda: sample(runtime, "pkwbus_drive_alarm", **labels) == 1)
                view = (await client.get("/api/v1/drives")).json()
                press = next(d for d in view if d["name"] == "press")
                (alarm,) = press["alarms"]
                assert (alarm["code"], alarm["text"], alarm["kind"]) == (
                    "16-90 bit 2", "Earth fault", "alarm"
                )  # fmt: skip
                assert alarm["parameter"] == "16-90" and alarm["since"] > 0
                saw = next(d for d in view if d["name"] == "saw")
                assert saw["alarms"] == []  # the other drive is not in alarm
                assert any("alarm 16-90 bit 2 Earth fault" in r.message for r in caplog.records)
                # Reset at the drive: the alarm goes, its series with it.
                sim.drives[1].model.reset()
                await until(lambda: sample(runtime, "pkwbus_drive_alarm", drive="press") is None)
                view = (await client.get("/api/v1/drives")).json()
                assert next(d for d in view if d["name"] == "press")["alarms"] == []
                assert any("is gone" in r.message for r in caplog.records)
    finally:
        await server.close()


USS_DRIVES = """
      - name: conveyor
        address: 3
        dialect: uss
        pkw_words: 4
        catalog: siemens-g120
        poll: [{parameter: "r0947[0]", every: 100ms}, {parameter: r0021, every: 100ms}]
"""


def test_the_sinamics_fault_numbers_against_the_list_manual() -> None:
    # SINAMICS G120 CU240B-2/CU240E-2 List Manual 02/2023: F30001 "Power unit: Overcurrent";
    # r0947 holds the number without its letter (LH9 3.1.1: F01003 = 1003).
    table = alarm_table("siemens-g120")
    assert table is not None
    faults, alarms = table.decoder(947), table.decoder(2122)
    assert faults is not None and alarms is not None
    assert [(a.code, a.text) for a in faults.decode(30001)] == [
        ("F30001", "Power unit: Overcurrent")
    ]
    assert [(a.code, a.text, a.kind) for a in alarms.decode(7409)] == [
        ("A07409", "Drive: U/f control, current limiting controller active", "warning")
    ]
    assert [(a.code, a.text) for a in faults.decode(1)] == [("F00001", "")]  # unexplained
    assert faults.decode(0) == ()


# Common SINAMICS faults, each with the text its table gives it (source S-CU240-LM).
COMMON_FAULTS = (7011, 7801, 30001, 30002, 30004, 30005, 30011, 30021)


@pytest.mark.parametrize("number", COMMON_FAULTS)
def test_a_fault_number_is_shown_in_words_as_an_alarm_number_is(number: int) -> None:
    """r0947 (faults, F) and r2122 (alarms, A) are told in words the same way: what the
    status page shows of the polled value (``said``, its ``shown``), and the alarm."""
    table = alarm_table("siemens-g120")
    assert table is not None
    faults, alarms = table.decoder(947), table.decoder(2122)
    assert isinstance(faults, CodeTable) and isinstance(alarms, CodeTable)
    assert faults.source == alarms.source  # the same List Manual, cited in its sources
    text = faults.texts[number]
    assert text.strip()
    assert said(faults, number) == f"F{number:05d} {text}"
    assert said(alarms, 7409) == f"A07409 {alarms.texts[7409]}"
    writer = _writer("pump", "siemens-g120", (947, "r0947"), (2122, "r2122"))
    _landed(writer, "pump", "r0947", number, 1000.0)
    (active,) = writer.snapshot.alarms["pump"]
    assert (active.alarm.code, active.alarm.text, active.alarm.kind) == (
        f"F{number:05d}", text, "alarm"
    )  # fmt: skip


async def test_a_sinamics_fault_number_is_shown_in_words_until_acknowledged() -> None:
    calm = ModelConfig(trip_rate=0.0, warning_rate=0.0, trip_reset_seconds=0.0)
    sim = Simulator("uss", [3], timing=SimTiming(response_delay=0.001), catalog="siemens-g120",
                    model=calm)  # fmt: skip
    server = await sim.serve_tcp("127.0.0.1", 0)
    line = fc_line("l2", server.url, USS_DRIVES).replace("protocol: fc", "protocol: uss")
    try:
        async with running(f"lines:{line}") as runtime:
            labels = {"drive": "conveyor", "code": "F30001", "text": "Power unit: Overcurrent",
                      "kind": "alarm"}  # fmt: skip
            await until(lambda: sample(runtime, "pkwbus_parameter_value", drive="conveyor",
                                       parameter="r0947") == 0)  # fmt: skip
            sim.drives[3].model.trip(30001, 0)
            await until(lambda: sample(runtime, "pkwbus_drive_alarm", **labels) == 1)
            (active,) = runtime.snapshot.alarms["conveyor"]
            assert active.alarm.shown == "F30001 Power unit: Overcurrent"
            sim.drives[3].model.reset()  # acknowledged: out of the current entries
            await until(lambda: sample(runtime, "pkwbus_drive_alarm", drive="conveyor") is None)
    finally:
        await server.close()
