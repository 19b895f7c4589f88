"""Data record 47 over DP-V1: the master's slave state machine against the simulated
DP-V1 slave, frame by frame through the wire format."""

from __future__ import annotations

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import (
    DpSlave,
    NoAnswer,
    SlaveSetup,
    SlaveState,
    TransferEnded,
)
from pkwbus.protocol.profibus.dpv1.msac import Dpv1Setup
from pkwbus.protocol.profibus.dpv1.transfer import RecordFailed, RecordRead
from pkwbus.protocol.profidrive.parameters import (
    AXES,
    RECORD,
    Attribute,
    Change,
    Format,
    ParameterAddress,
    ParameterError,
    ParameterRequest,
    Values,
    decode_response,
)
from pkwbus.sim import ModelConfig
from pkwbus.sim.drives.profidrive_buffer import BufferKind
from pkwbus.sim.profibus.line import DpSimulator
from tests.sim.conftest import FakeClock
from tests.sim.test_dp_line import Wire

MASTER, ADDRESS = 2, 5


class Bus:
    """One master-side slave and the simulated line, one frame at a time."""

    def __init__(self, sim: DpSimulator, *, dpv1: bool = True, timeout: float = 1.0) -> None:
        self.sim = sim
        setup = Dpv1Setup(response_timeout=timeout) if dpv1 else None
        prm = dps.Parameters(sim.ident, dps.watchdog_factors(1.0))
        self.slave = DpSlave(SlaveSetup(ADDRESS, MASTER, prm, sim.ppo.cfg, dpv1=setup))
        self.now = 0.0
        self.acyclic: list[fdl.DataFrame] = []
        self.events: list[object] = []

    def send(self, frame: fdl.DataFrame | None) -> None:
        assert frame is not None
        answer = self.sim.handle(fdl.encode(frame))
        reply = NoAnswer() if answer is None else fdl.decode(answer)
        self.events += self.slave.feed(reply, self.now)

    def cycle(self) -> None:
        """A Data_Exchange (or start-up request), then the transfer's request if any."""
        self.now += 0.01
        self.send(self.slave.poll(self.now))
        frame = self.slave.poll_acyclic()
        while frame is not None:  # and its repeats at once, as the master sends them
            self.acyclic.append(frame)
            self.send(frame)
            frame = self.slave.repeat_acyclic()

    def start(self) -> None:
        for _ in range(6):
            self.cycle()
        assert self.slave.state is SlaveState.DATA_EXCHANGE

    def transfer(self, request: ParameterRequest, cycles: int = 30) -> RecordRead | RecordFailed:
        self.slave.start_transfer(0, RECORD, request.encode(), self.now)
        self.events.clear()
        for _ in range(cycles):
            self.cycle()
            ended = [e for e in self.events if isinstance(e, TransferEnded)]
            if ended:
                return ended[-1].end
        raise AssertionError("the transfer did not end")


def sim(dialect: str = "profidrive", *, not_ready: int = 0) -> DpSimulator:
    return DpSimulator([ADDRESS], dialect=dialect, ppo_number=3, dpv1=True, not_ready=not_ready)


@pytest.mark.parametrize("dialect", ["profidrive", "danfoss-pcv"])
def test_many_parameters_in_one_request(dialect: str) -> None:
    line = sim(dialect, not_ready=2)
    bus = Bus(line)
    bus.start()
    drive = line.drives[ADDRESS]
    pnus = sorted(drive.params.specs)[:8]
    request = ParameterRequest.read(1, AXES[dialect], [ParameterAddress(p) for p in pnus])
    end = bus.transfer(request)
    assert isinstance(end, RecordRead)
    assert end.reads == 3  # two "state conflict" answers, then the response
    response = decode_response(end.data, request)
    for pnu, result in zip(pnus, response.results, strict=True):
        spec = drive.params.specs[pnu]
        if spec.vtype.value == "text":
            assert isinstance(result, Values) and result.format is Format.OCTET_STRING
        elif spec.live is None:
            assert isinstance(result, Values)
            raw = drive.params.raw[pnu, 0]
            if result.format is Format.FLOAT:
                import struct

                assert struct.pack(">f", result.values[0]) == raw.to_bytes(4, "big")
            else:
                assert result.values[0] & 0xFFFFFFFF == raw
    # every acyclic frame went to SAP 51 and the slave stayed in data exchange
    assert all((f.dsap, f.ssap) == (51, 51) for f in bus.acyclic)
    assert bus.slave.state is SlaveState.DATA_EXCHANGE


def test_a_change_is_written_and_an_unknown_parameter_refused() -> None:
    line = sim()
    bus = Bus(line)
    bus.start()
    drive = line.drives[ADDRESS]
    # The G120X operating instructions' example, p1121 = 12.15 s, beside a parameter
    # the drive does not have.
    request = ParameterRequest.change(
        0x80, 1, [Change(ParameterAddress(1121), Values(Format.FLOAT, (12.15,))),
                  Change(ParameterAddress(9999), Values(Format.U16, (1,)))],
    )  # fmt: skip
    assert request.encode().startswith(bytes.fromhex("80 02 01 02 10 01 04 61 00 00"))
    end = bus.transfer(request)
    assert isinstance(end, RecordRead)
    response = decode_response(end.data, request)
    assert response.failed
    assert response.results[0] is None  # done
    error = response.results[1]
    assert isinstance(error, ParameterError) and error.number == 0
    assert error.text == "Illegal parameter number"
    assert drive.params.number(1121) == pytest.approx(12.15, abs=1e-5)


def test_a_read_only_parameter_is_not_changed() -> None:
    line = sim()
    bus = Bus(line)
    bus.start()
    before = line.drives[ADDRESS].params.raw[964, 0]
    request = ParameterRequest.change(
        6, 1, [Change(ParameterAddress(964), Values(Format.U16, (before ^ 1,)))]
    )
    end = bus.transfer(request)
    assert isinstance(end, RecordRead)
    (error,) = decode_response(end.data, request).results
    assert isinstance(error, ParameterError)
    assert error.text == "Parameter value cannot be changed"
    assert line.drives[ADDRESS].params.raw[964, 0] == before


def test_a_slave_that_does_not_answer_in_time_ends_the_transfer() -> None:
    bus = Bus(sim(not_ready=1000), timeout=0.1)
    bus.start()
    end = bus.transfer(ParameterRequest.read(3, 1, [ParameterAddress(2)]))
    assert isinstance(end, RecordFailed) and end.timed_out
    assert bus.slave.state is SlaveState.DATA_EXCHANGE  # the cycle goes on


def test_a_dpv0_slave_refuses_the_service_access_point() -> None:
    line = DpSimulator([ADDRESS], dialect="profidrive", ppo_number=3, dpv1=False)
    bus = Bus(line)
    bus.start()
    end = bus.transfer(ParameterRequest.read(3, 1, [ParameterAddress(2)]))
    assert isinstance(end, RecordFailed) and "does not run DP-V1" in end.why
    assert bus.slave.state is SlaveState.DATA_EXCHANGE


def test_a_restart_mid_request_ends_the_transfer_and_the_slave_comes_back() -> None:
    line = sim(not_ready=3)
    bus = Bus(line)
    bus.start()
    bus.slave.start_transfer(
        0, RECORD, ParameterRequest.read(4, 1, [ParameterAddress(2)]).encode(), bus.now
    )
    bus.cycle()
    line.restart(ADDRESS)
    for _ in range(12):
        bus.cycle()
    ended = [e.end for e in bus.events if isinstance(e, TransferEnded)]
    assert len(ended) == 1 and isinstance(ended[0], RecordFailed)
    assert bus.slave.state is SlaveState.DATA_EXCHANGE
    assert bus.transfer(ParameterRequest.read(5, 1, [ParameterAddress(2)])).__class__ is RecordRead


def test_a_transfer_needs_a_dpv1_slave_in_data_exchange() -> None:
    bus = Bus(sim(), dpv1=False)
    bus.start()
    with pytest.raises(LocalProtocolError, match="no DP-V1 slave"):
        bus.slave.start_transfer(0, RECORD, b"\x01\x01\x01\x01", bus.now)
    fresh = Bus(sim())
    with pytest.raises(LocalProtocolError, match="not in data exchange"):
        fresh.slave.start_transfer(0, RECORD, b"\x01\x01\x01\x01", 0.0)


def test_a_transfer_ends_at_its_timeout_while_the_slave_keeps_its_diagnosis() -> None:
    # The slave answers its Data_Exchange "diagnosis waiting", then static diagnosis on
    # every Slave_Diag: the transfer cannot go on, and ends once its time is up.
    from pkwbus.protocol.profibus.dp.services import Diagnosis, encode_diagnosis
    from pkwbus.protocol.profibus.fdl import DataFrame, Status, response_fc

    line = sim()
    bus = Bus(line, timeout=0.1)
    bus.start()
    slave = bus.slave
    request = ParameterRequest.read(3, 1, [ParameterAddress(2)]).encode()
    slave.start_transfer(0, RECORD, request, bus.now)
    inputs = bytes(slave.setup.inputs)
    diag = encode_diagnosis(Diagnosis(frozenset({"stat_diag"}), MASTER, line.ident))
    events = []
    for _ in range(100):  # a second of cycles
        bus.now += 0.01
        frame = slave.poll(bus.now)
        assert frame is not None
        if frame.dsap is None:
            answer = DataFrame(MASTER, ADDRESS, response_fc(Status.DH), data=inputs)
        else:
            answer = DataFrame(MASTER, ADDRESS, response_fc(Status.DL), 62, 60, diag)
        events += slave.feed(answer, bus.now)
        assert slave.poll_acyclic() is None
    ended = [e.end for e in events + slave.take_events() if isinstance(e, TransferEnded)]
    assert len(ended) == 1 and isinstance(ended[0], RecordFailed) and ended[0].timed_out
    assert slave.state is SlaveState.DATA_EXCHANGE


# ------------------------------------------------- a PROFIdrive fault buffer, any make

STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0, trip_reset_seconds=0.0)  # as told


def buffered(kind: BufferKind, clock: FakeClock, *, ppo_number: int = 3) -> DpSimulator:
    return DpSimulator(
        [ADDRESS], ppo_number=ppo_number, dpv1=ppo_number == 3, clock=clock, model=STEADY,
        fault_buffers={ADDRESS: kind},
    )  # fmt: skip


def test_an_8_x_8_buffer_with_time_differences_through_data_record_47() -> None:
    clock = FakeClock(0.0)
    line = buffered(BufferKind(8, 8, 53), clock)
    drive = line.drives[ADDRESS]
    clock.advance(100_000.25)  # a day and 13,600.25 s of runtime: ms past 16 bits
    drive.trip(7, clock(), value=-5)
    drive.trip(8, clock(), value=6)  # the same fault situation, its second message
    drive.acknowledge(clock())
    clock.advance(1.5)
    drive.trip(9, clock(), value=7)
    bus = Bus(line)
    bus.start()
    request = ParameterRequest.read(1, 1, [
        ParameterAddress(944), ParameterAddress(950, 0, 2),
        ParameterAddress(948, 1, 1, Attribute.DESCRIPTION),
        ParameterAddress(947, 0, 10), ParameterAddress(948, 8, 2), ParameterAddress(949, 8, 2),
        ParameterAddress(948, 0), ParameterAddress(947, 64),
    ])  # fmt: skip
    end = bus.transfer(request)
    assert isinstance(end, RecordRead)
    counter, shape, ident, numbers, times, values, now_time, beyond = decode_response(
        end.data, request
    ).results
    assert counter == Values(Format.U16, (4,))  # three faults and an acknowledgement
    assert shape == Values(Format.U16, (8, 8))
    assert ident == Values(Format.U16, (53 | 1 << 14 | 1 << 9,))  # array, read-only
    assert numbers == Values(Format.U16, (9, 0, 0, 0, 0, 0, 0, 0, 7, 8))
    ms = 100_000_250 - 86_400_000
    assert times == Values(Format.TIME_DIFFERENCE_WITH_DATE, (ms << 16 | 1, ms << 16 | 1))
    assert values == Values(Format.I32, (-5, 6))
    assert now_time == Values(Format.TIME_DIFFERENCE_WITH_DATE, ((ms + 1500) << 16 | 1,))
    assert isinstance(beyond, ParameterError) and beyond.text == "Invalid subindex"


def pkw_read(wire: Wire, clock: FakeClock, request: pkw.PkwRequest) -> pkw.PkwResponse:
    """One PKW job through the PPO's words, the line's clock going on with the cycles."""
    wire.events.clear()
    wire.slot.submit(request)
    for _ in range(30):
        clock.advance(0.01)
        wire.cycle(clock())
        done = [e for e in wire.events if isinstance(e, ppo.SlotAnswer)]
        if done:
            return done[0].response
    raise AssertionError("no answer")


def test_an_8_x_1_buffer_with_seconds_since_through_the_ppo_pkw_words() -> None:
    clock = FakeClock(0.0)
    line = buffered(BufferKind(8, 1, 6), clock, ppo_number=1)
    drive = line.drives[ADDRESS]
    dialect = line.dialect
    drive.trip(21, clock(), value=3)
    drive.acknowledge(clock())
    clock.advance(30.0)
    drive.trip(22, clock(), value=4)
    clock.advance(100.0)
    wire = Wire(line, ADDRESS)
    for _ in range(4):
        clock.advance(0.01)
        wire.cycle(clock())

    def read(pnu: int, index: int) -> int:
        answer = pkw_read(wire, clock, pkw.read(dialect, pnu, index))
        assert isinstance(answer, pkw.ValueResponse), answer
        return answer.raw

    ident = pkw_read(wire, clock, pkw.read_description(dialect, 948, 1))
    assert isinstance(ident, pkw.DescriptionResponse) and ident.raw == 6 | 1 << 14 | 1 << 9
    assert (read(950, 0), read(950, 1)) == (8, 1)
    assert [read(947, i) for i in range(3)] == [22, 21, 0]  # [0] active, [1] acknowledged
    assert (read(948, 0), read(948, 1)) == (100, 130)  # seconds since each fault
    assert read(949, 1) == 3 and read(944, 0) == 3


def test_a_time_difference_with_date_does_not_fit_the_pkw_words() -> None:
    clock = FakeClock(0.0)
    line = buffered(BufferKind(8, 8, 53), clock, ppo_number=1)
    line.drives[ADDRESS].trip(5, clock(), value=0)
    wire = Wire(line, ADDRESS)
    for _ in range(4):
        clock.advance(0.01)
        wire.cycle(clock())
    assert isinstance(pkw_read(wire, clock, pkw.read(line.dialect, 948, 0)), pkw.Rejection)
    number = pkw_read(wire, clock, pkw.read(line.dialect, 947, 0))
    assert isinstance(number, pkw.ValueResponse) and number.raw == 5


def test_a_buffer_kind_the_simulator_does_not_keep_is_refused() -> None:
    with pytest.raises(ValueError, match="data type 12"):
        BufferKind(8, 1, 12)
    with pytest.raises(ValueError, match="not here"):
        DpSimulator([5], fault_buffers={6: BufferKind()})
