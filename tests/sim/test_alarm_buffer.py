"""The simulated SINAMICS alarm buffer, checked against the documents' statements: the
alarms there at r2122[0..7], the oldest at [0], sorted by time received; eight there and
another: [7] overwritten (G120C Operating Instructions 09/2017, section 8.3); a gone alarm
moved at once into the history, the latest at [8] (G220 Operating Instructions 04/2024,
section 15.6), [63] the oldest (G120 parameter descriptions, r2122); r2121 counting every
change (the same descriptions); times in the runtime base r2114."""

from __future__ import annotations

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw import ValueResponse
from pkwbus.protocol.pkw.dialects import USS
from pkwbus.protocol.serial.telegram import BlockShape, split_block
from pkwbus.sim import ModelConfig, SimDrive, Simulator
from pkwbus.sim.drives.model import BUFFERED_ALARMS, WARNING_BITS
from tests.sim.conftest import FakeClock, parse, request_telegram

STILL = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0, trip_reset_seconds=0.0)
CODE, VALUE, RECEIVED_MS, RECEIVED_DAYS, REMOVED_MS = 2122, 2124, 2123, 2145, 2125


def sim_of(clock: FakeClock, model: ModelConfig = STILL) -> Simulator:
    return Simulator("uss", [3], seed=5, model=model, clock=clock, pkw_words=4)


def codes(drive: SimDrive, indexes: range) -> list[int]:
    return [drive.value(CODE, i) for i in indexes]


def test_the_alarms_there_the_oldest_first_and_the_gone_ones_the_latest_first() -> None:
    clock = FakeClock()
    sim = sim_of(clock)
    drive = sim.drives[3]
    assert codes(drive, range(64)) == [0] * 64 and drive.value(2121) == 0
    a, b, c = (BUFFERED_ALARMS[bit] for bit in WARNING_BITS)
    sim.warn(3, WARNING_BITS[0])  # a comes
    clock.advance(2)
    sim.warn(3, WARNING_BITS[1])  # a goes, b comes
    clock.advance(2)
    sim.warn(3, WARNING_BITS[2])  # b goes, c comes
    assert codes(drive, range(10)) == [c, 0, 0, 0, 0, 0, 0, 0, b, a]
    # Each alarm that came and each that went is one change.
    assert drive.value(2121) == 5
    # Times received and removed in the runtime base: b came at 2 s and went at 4 s.
    assert (drive.value(RECEIVED_MS, 8), drive.value(REMOVED_MS, 8)) == (2000, 4000)
    assert drive.value(REMOVED_MS, 0) == 0  # c is there: not removed


def test_eight_alarms_there_and_another_overwrite_the_eighth_place() -> None:
    clock = FakeClock()
    drive = sim_of(clock).drives[3]
    buffer = drive.model.alarms
    for n in range(10):
        buffer.come(7900 + n, n, 1000 * n)
    assert codes(drive, range(9)) == [7900, 7901, 7902, 7903, 7904, 7905, 7906, 7909, 0]
    assert drive.value(2121) == 10


def test_the_history_keeps_56_the_oldest_dropped_and_the_counter_wraps() -> None:
    clock = FakeClock()
    drive = sim_of(clock).drives[3]
    buffer = drive.model.alarms
    buffer.changes = 65_530
    for n in range(60):
        buffer.come(7000 + n, n, 1000 * n)
        buffer.go(7000 + n, 1000 * n + 500)
    assert codes(drive, range(8)) == [0] * 8
    assert codes(drive, range(8, 64)) == [7000 + n for n in reversed(range(4, 60))]
    assert drive.value(2121) == (65_530 + 120) % 65_536


def test_the_buffer_is_read_over_the_wire_in_days_and_ms() -> None:
    clock = FakeClock()
    sim = sim_of(clock)
    clock.advance(86_400 + 1)
    sim.warn(3, WARNING_BITS[0])

    def read(pnu: int, index: int = 0) -> int:
        answer = parse(sim.handle(request_telegram(3, pkw.read(USS, pnu, index), USS)))
        resp = pkw.decode_response(split_block(answer.data, BlockShape(4, 2)).pkw, USS, sim.layout)
        assert isinstance(resp, ValueResponse) and resp.pnu == pnu
        return resp.raw

    code = BUFFERED_ALARMS[WARNING_BITS[0]]
    assert [read(CODE, 0), read(RECEIVED_MS, 0), read(RECEIVED_DAYS, 0), read(2121)] == [
        code, 1_000, 1, 1,
    ]  # fmt: skip
    assert read(VALUE, 0) > 0  # the output current at the warning, in 0.01 A


def test_random_warnings_come_and_go_through_the_buffer() -> None:
    clock = FakeClock()
    model = ModelConfig(noise=0.0, warning_rate=1 / 60, warning_seconds=20.0, trip_rate=0.0)
    sim = sim_of(clock, model)
    drive = sim.drives[3]
    for _ in range(3600):
        clock.advance(1)
        drive.tick(clock())
    buffer = drive.model.alarms
    assert len(buffer.history) > 20  # about one a minute, each gone after 20 s
    assert len(buffer.there) <= 1 and drive.value(2121) >= 2 * len(buffer.history)
    there = codes(drive, range(1))[0]
    assert (there != 0) == bool(drive.model.warning_word)
