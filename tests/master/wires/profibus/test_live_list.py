"""The live list's wire as pure calls: what it asks each address, and what it makes of the
answers (EN 50170 vol. 2 part 4: FDL status, then a slave's Slave_Diag)."""

from __future__ import annotations

from pkwbus.master.events import Event, StationAsked, StationFound, StationsAsked
from pkwbus.master.planning.plan import Idle
from pkwbus.master.planning.planner import Planner
from pkwbus.master.wires.profibus.live_list import LiveListWire
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import Answer, NoAnswer
from pkwbus.protocol.profibus.fdl import DataFrame, StationType
from pkwbus.sim.profibus.line import DpSimulator

MASTER = 2


def run(wire: LiveListWire, answer: object) -> tuple[list[DataFrame], list[Event]]:
    """Every request the wire sends until it has asked every station; ``answer(frame)``
    answers each."""
    planner = Planner([], poll_deadline=1.0)
    sent: list[DataFrame] = []
    events: list[Event] = []
    for _ in range(100):
        request = wire.transmit(planner, 0.0)
        events += wire.take_events()
        if isinstance(request, Idle):
            return sent, events
        sent.append(request)
        wire.received(planner, request, answer(request), 0.0, 0.0, 0.0)  # type: ignore[operator]
        events += wire.take_events()
    raise AssertionError("the live list never ended")


def test_masters_slaves_and_empty_addresses() -> None:
    sim = DpSimulator([8], dialect="danfoss-pcv", seed=3)

    def answer(frame: DataFrame) -> Answer:
        if frame.da == 5:  # another master, ready for the ring
            fc = fdl.response_fc(fdl.Status.OK, StationType.MASTER_READY)
            return DataFrame(MASTER, 5, fc)
        raw = sim.handle(fdl.encode(frame))
        return NoAnswer() if raw is None else fdl.decode(raw)  # type: ignore[return-value]

    wire = LiveListWire(MASTER, [3, 5, 8], tries=2)
    sent, events = run(wire, answer)
    assert {f.sa for f in sent} == {MASTER}  # every request from the master it was given
    found = [e for e in events if isinstance(e, StationFound)]
    assert [(e.address, e.station_type) for e in found] == [
        (5, StationType.MASTER_READY),
        (8, StationType.SLAVE),
    ]
    diagnosis = found[1].diagnosis
    assert diagnosis is not None and diagnosis.ident == sim.ident and diagnosis.master is None
    asked = [(e.address, e.place, e.count) for e in events if isinstance(e, StationAsked)]
    assert asked == [(3, 1, 3), (5, 2, 3), (8, 3, 3)]
    assert isinstance(events[-1], StationsAsked)
    # Address 3 asked twice (its tries), then 5 once, then 8: status and diagnosis.
    status = fdl.request_fc(fdl.Function.FDL_STATUS)
    assert [(f.da, f.fc == status) for f in sent] == [
        (3, True), (3, True), (5, True), (8, True), (8, False),
    ]  # fmt: skip
    assert sent[-1].dsap == dps.Service.SLAVE_DIAG
    # Nothing was parametrised: no Set_Prm, no Chk_Cfg, no data exchange.
    assert all(f.dsap in (None, dps.Service.SLAVE_DIAG) and not f.data for f in sent)


def test_a_slave_without_a_readable_diagnosis_is_listed_without_one() -> None:
    def answer(frame: DataFrame) -> Answer:
        if frame.dsap == dps.Service.SLAVE_DIAG:
            return NoAnswer()
        return DataFrame(MASTER, frame.da, fdl.response_fc(fdl.Status.OK))

    _, events = run(LiveListWire(MASTER, [9], tries=3), answer)
    found = [e for e in events if isinstance(e, StationFound)]
    assert found == [StationFound(9, StationType.SLAVE, None)]
