"""The simulated drives' own logs, checked against the documents' statements: the SINAMICS
fault buffer (S200 Operating Instructions appendix A.3; r2114 after the CU240D-2 Operating
Instructions section 8.2), the Danfoss alarm log 15-30..15-32 (newest first, 10 entries:
a secondary source, kept so by the simulator) and the MICROMASTER 4 fault buffer (against
the test's model of its documents, tests/protocol/logs/test_micromaster.py)."""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol import pkw
from pkwbus.protocol.logs import Read
from pkwbus.protocol.pkw import ValueResponse
from pkwbus.protocol.pkw.dialects import FC, USS
from pkwbus.protocol.pzd import Profile
from pkwbus.protocol.serial.telegram import BlockShape, split_block
from pkwbus.sim import ModelConfig, SimDrive, Simulator
from pkwbus.sim.drives.model import ALARMS, DriveModel, Limits
from tests.protocol.logs.test_micromaster import Mm4Buffer
from tests.sim.conftest import FakeClock, parse, request_telegram

STILL = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0, trip_reset_seconds=0.0)
DAY = 86_400  # seconds
DAY_MS = 86_400_000
BUFFER = (947, 949, 948, 2130, 2109, 2136)  # number, value, received ms/days, removed ms/days
RUNNING_CURRENT = 21.0 * (0.3 + 0.7 * 0.8**2)  # the model's current at 80 % of the maximum


def sim_of(protocol: str, clock: FakeClock, model: ModelConfig = STILL) -> Simulator:
    return Simulator(protocol, [3], seed=5, model=model, clock=clock, pkw_words=4)


def values(drive: SimDrive, pnu: int, indexes: range) -> list[int]:
    return [drive.value(pnu, i) for i in indexes]


def case(drive: SimDrive, number: int, pnu: int = 947) -> list[int]:
    """Fault case ``number`` (0 the active one, k the k-th acknowledged) of ``pnu``."""
    return values(drive, pnu, range(8 * number, 8 * number + 8))


def runtime(sim: Simulator) -> tuple[int, int]:
    """r2114 now: (ms, days)."""
    drive = sim.drives[3]
    drive.tick(sim.clock())
    return drive.value(2114, 0), drive.value(2114, 1)


# ------------------------------------------------------------ SINAMICS fault buffer


def test_64_entries_the_active_case_first_in_the_order_the_faults_came() -> None:
    clock = FakeClock()
    sim = sim_of("uss", clock)
    drive = sim.drives[3]
    assert all(values(drive, pnu, range(64)) == [0] * 64 for pnu in BUFFER)
    for code in (7801, 30001, 7900):
        sim.trip(3, code)
        clock.advance(1)
    assert case(drive, 0) == [7801, 30001, 7900, 0, 0, 0, 0, 0]
    assert values(drive, 947, range(8, 64)) == [0] * 56
    for pnu in BUFFER[1:]:  # an empty place reads 0 in every buffer parameter
        assert case(drive, 0, pnu)[3:] == [0] * 5 and values(drive, pnu, range(8, 64)) == [0] * 56
    assert drive.params.specs[947].array == 64


def test_an_acknowledgement_moves_every_case_one_down_and_drops_the_seventh() -> None:
    clock = FakeClock()
    sim = sim_of("uss", clock)
    drive = sim.drives[3]
    sim.trip(3, 101)
    sim.trip(3, 102)
    sim.acknowledge(3)
    assert case(drive, 0) == [0] * 8  # the active case is then empty
    assert case(drive, 1) == [101, 102, 0, 0, 0, 0, 0, 0]
    for code in range(201, 209):  # eight more fault cases of one fault each
        clock.advance(10)
        sim.trip(3, code)
        sim.acknowledge(3)
    # newest acknowledged case first: 208 at [8], ..., 202 at [56]; 201 and 101/102 are gone
    assert [drive.value(947, 8 * k) for k in range(1, 8)] == list(range(208, 201, -1))
    assert 101 not in values(drive, 947, range(64)) and 201 not in values(drive, 947, range(64))
    assert case(drive, 0) == [0] * 8


def test_beyond_eight_active_faults_only_the_eighth_place_is_overwritten() -> None:
    sim = sim_of("uss", FakeClock())
    drive = sim.drives[3]
    for code in range(1, 11):
        sim.trip(3, code, value=-code)
    assert case(drive, 0) == [1, 2, 3, 4, 5, 6, 7, 10]
    assert case(drive, 0, 949) == [-c & 0xFFFFFFFF for c in (1, 2, 3, 4, 5, 6, 7, 10)]
    sim.acknowledge(3)
    assert case(drive, 1) == [1, 2, 3, 4, 5, 6, 7, 10]


def test_r0944_counts_each_change_of_the_buffer_and_wraps() -> None:
    sim = sim_of("uss", FakeClock())
    drive = sim.drives[3]
    assert drive.value(944) == 0
    for code in range(1, 10):  # the ninth overwrites the eighth place: a change too
        sim.trip(3, code)
        assert drive.value(944) == code
    sim.acknowledge(3)
    assert drive.value(944) == 10
    sim.acknowledge(3)  # nothing active: nothing changes
    assert drive.value(944) == 10
    drive.model.faults.changes = 0xFFFF
    sim.trip(3, 1)
    assert drive.value(944) == 0  # Unsigned16


def test_r2114_rolls_over_into_days_and_starts_again_at_a_power_cycle() -> None:
    clock = FakeClock()
    sim = sim_of("uss", clock)
    assert runtime(sim) == (0, 0)
    clock.advance(DAY - 0.001)
    assert runtime(sim) == (DAY_MS - 1, 0)
    clock.advance(0.001)  # at 86,400,000 ms: r2114[0] goes to 0 and r2114[1] + 1
    assert runtime(sim) == (0, 1)
    clock.advance(1.5 * DAY)
    assert runtime(sim) == (DAY_MS // 2, 2)
    sim.power_cycle(3)
    assert runtime(sim) == (0, 0)
    clock.advance(12.345)
    assert runtime(sim) == (12_345, 0)


def test_many_small_steps_add_up_to_the_exact_runtime() -> None:
    model = DriveModel(Profile.PROFIDRIVE, random.Random(1), STILL, now=1000.0)
    for step in range(1, 36_001):
        model.update(1000.0 + step * 0.1, Limits())
    assert model.runtime_ms == 3_600_000


def test_received_and_removed_times_are_the_runtime_at_trip_and_acknowledgement() -> None:
    clock = FakeClock()
    sim = sim_of("uss", clock)
    drive = sim.drives[3]
    clock.advance(DAY + 5.25)
    sim.trip(3, 7801)
    at_trip = runtime(sim)
    assert at_trip == (5_250, 1)
    assert (drive.value(948, 0), drive.value(2130, 0)) == at_trip
    assert (drive.value(2109, 0), drive.value(2136, 0)) == (0, 0)  # not removed yet
    clock.advance(2 * DAY + 0.5)
    sim.acknowledge(3)
    at_acknowledgement = runtime(sim)
    assert at_acknowledgement == (5_750, 3)
    assert (drive.value(948, 8), drive.value(2130, 8)) == at_trip
    assert (drive.value(2109, 8), drive.value(2136, 8)) == at_acknowledgement
    sim.power_cycle(3)  # the buffer is kept; the runtime starts again
    clock.advance(7)
    sim.trip(3, 7802)
    assert (drive.value(948, 0), drive.value(2130, 0)) == (7_000, 0)
    assert (drive.value(948, 8), drive.value(2130, 8)) == at_trip


def test_the_reset_after_trip_reset_seconds_acknowledges_at_its_runtime() -> None:
    clock = FakeClock()
    sim = sim_of("uss", clock, ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0))
    drive = sim.drives[3]
    clock.advance(2)
    sim.trip(3, 7801)
    assert drive.tripped and drive.value(947, 0) == 7801
    clock.advance(31)
    assert runtime(sim) == (33_000, 0)  # the tick resets: 30 s after the trip
    assert not drive.tripped and case(drive, 0) == [0] * 8
    assert (drive.value(947, 8), drive.value(948, 8), drive.value(2109, 8)) == (7801, 2000, 33000)


def test_the_buffer_is_read_over_the_wire() -> None:
    clock = FakeClock()
    sim = sim_of("uss", clock)
    clock.advance(DAY + 1)
    sim.trip(3, 7801)
    sim.acknowledge(3)

    def read(pnu: int, index: int) -> int:
        answer = parse(sim.handle(request_telegram(3, pkw.read(USS, pnu, index), USS)))
        resp = pkw.decode_response(split_block(answer.data, BlockShape(4, 2)).pkw, USS, sim.layout)
        assert isinstance(resp, ValueResponse) and resp.pnu == pnu
        return resp.raw

    assert [read(947, 0), read(947, 8), read(2130, 8), read(944, 0)] == [0, 7801, 1, 2]
    assert (read(2114, 0), read(2114, 1)) == (1_000, 1)


# -------------------------------------------------------------- Danfoss alarm log


def fc_read(sim: Simulator, pnu: int, index: int = 0) -> int:
    answer = parse(sim.handle(request_telegram(3, pkw.read(FC, pnu, index), FC)))
    resp = pkw.decode_response(split_block(answer.data, BlockShape(None, 2)).pkw, FC, sim.layout)
    assert isinstance(resp, ValueResponse) and resp.pnu == pnu
    return resp.raw


def test_danfoss_alarm_log_newest_first_ten_entries_the_oldest_dropped() -> None:
    clock = FakeClock()
    sim = sim_of("fc", clock)
    drive = sim.drives[3]
    for pnu in (1530, 1531, 1532):
        assert values(drive, pnu, range(10)) == [0] * 10  # empty entries read 0
    for code in range(1, 13):
        clock.advance(10)  # running again at 40 Hz of 50 after 4 s of ramp
        sim.trip(3, code)
        sim.acknowledge(3)  # an acknowledgement removes nothing
    assert values(drive, 1530, range(10)) == list(range(12, 2, -1))
    assert values(drive, 1532, range(10)) == [10 * c for c in range(12, 2, -1)]  # seconds
    assert values(drive, 1531, range(10)) == [round(RUNNING_CURRENT * 100)] * 10  # 0.01 A
    assert fc_read(sim, 1530, 0) == 12 and fc_read(sim, 1530, 9) == 3


def test_a_trip_while_stopped_logs_no_current_and_a_given_value_is_kept() -> None:
    clock = FakeClock()
    sim = sim_of("fc", clock)
    drive = sim.drives[3]
    sim.trip(3, 13)
    clock.advance(1)
    sim.trip(3, 14)  # the motor coasted at the first trip
    sim.trip(3, 4, value=-7)
    assert values(drive, 1530, range(4)) == [4, 14, 13, 0]
    assert values(drive, 1531, range(3)) == [-7 & 0xFFFFFFFF, 0, round(RUNNING_CURRENT * 100)]
    assert drive.value(1690) == 1 << 6 | 1 << 2 | 1 << 14  # the codes' bits of 16-90


def test_a_power_cycle_counts_in_15_03_and_keeps_the_log() -> None:
    clock = FakeClock()
    sim = sim_of("fc", clock)
    assert fc_read(sim, 1503) == 1
    clock.advance(100)
    sim.trip(3, 13)
    sim.power_cycle(3)
    sim.power_cycle(3)
    assert fc_read(sim, 1503) == 3
    clock.advance(50)
    sim.trip(3, 14)
    assert [fc_read(sim, 1530, i) for i in range(3)] == [14, 13, 0]
    assert [fc_read(sim, 1532, i) for i in range(2)] == [150, 100]  # operating time goes on


# ------------------------------------------------------------------ random trips


@pytest.mark.parametrize("profile", [Profile.FC, Profile.PROFIDRIVE])
def test_random_trips_and_their_resets_land_in_the_logs(profile: Profile) -> None:
    config = ModelConfig(warning_rate=0.0, trip_rate=1 / 300, trip_reset_seconds=30)
    model = DriveModel(profile, random.Random(11), config)
    trips = resets = 0
    for second in range(1, 4 * 3600 + 1):
        was = model.tripped
        model.update(float(second), Limits())
        trips += model.tripped and not was
        resets += was and not model.tripped
    codes = {code for code, _ in ALARMS[profile]}
    assert trips > 20 and resets >= trips - 1
    assert model.faults.changes == trips + resets  # below 65536: no wrap
    # one fault a case (a random trip waits for the reset): 7 acknowledged, and the active one
    entered = [f.number for c in model.faults.cases for f in c]
    assert len(entered) == 7 + model.tripped and set(entered) <= codes
    assert len(model.alarm_log) == 10 and set(model.alarm_log) <= codes


# ------------------------------------------------------------------- the test hook


def test_simulator_trip_refuses_what_no_drive_could_log() -> None:
    sim = sim_of("uss", FakeClock())
    for code in (0, 0x10000):
        with pytest.raises(ValueError, match="outside 1-65535"):
            sim.trip(3, code)
    with pytest.raises(ValueError, match="signed 32-bit"):
        sim.trip(3, 1, value=1 << 31)
    with pytest.raises(ValueError, match="no simulated drive at address 4"):
        sim.trip(4, 1)
    for call in (sim.acknowledge, sim.power_cycle):
        with pytest.raises(ValueError, match="no simulated drive at address 4"):
            call(4)
    assert sim.drives[3].value(944) == 0


@pytest.mark.parametrize(
    ("protocol", "catalog", "pnus"),
    [
        ("uss", "siemens-g120", (944, 947, 948, 949, 2109, 2114, 2130, 2136)),
        ("fc", "danfoss-fc", (1503, 1530, 1531, 1532)),
        ("uss", "siemens-mm4", (947, 948, 949, 952, 2114)),
    ],
)
def test_the_logs_are_served_with_the_default_catalogs(
    protocol: str, catalog: str, pnus: tuple[int, ...]
) -> None:
    """``pkwbus simulate`` serves with these catalogs: the logs stay the model's."""
    sim = Simulator(protocol, [3], seed=5, model=STILL, clock=FakeClock(), catalog=catalog)
    sim.trip(3, 13, value=9)
    specs = sim.drives[3].params.specs
    assert all(specs[pnu].live is not None for pnu in pnus)
    code, value = {"uss": (947, 949), "fc": (1530, 1531)}[protocol]
    assert (sim.drives[3].value(code, 0), sim.drives[3].value(value, 0)) == (13, 9)


# ------------------------------------------------------------------ a drive's past


def test_a_drive_made_with_a_past_has_its_trips_acknowledged_hours_ago() -> None:
    """``past_trips``: the demo's drives show logs from the first minute, in the documents'
    layout (acknowledged cases; the Danfoss log newest first) and time bases."""
    clock = FakeClock()
    past = dataclasses.replace(STILL, past_trips=2)
    uss = sim_of("uss", clock, past).drives[3]
    assert case(uss, 0) == [0] * 8  # nothing active
    older, newer = case(uss, 2)[0], case(uss, 1)[0]
    assert older and newer
    hour = 3_600_000
    assert uss.value(948, 16) == hour and uss.value(948, 8) == 7 * hour  # received, by runtime
    assert uss.value(2109, 8) == 7 * hour + 60_000  # acknowledged a minute later
    assert runtime(sim_of("uss", clock, past)) == (13 * hour, 0)  # the last trip 6 h ago
    fc = sim_of("fc", clock, past).drives[3]
    assert [fc.value(1530, i) for i in range(3)][2] == 0 and fc.value(1530, 1)
    assert fc.value(1532, 0) == 7 * 3600 and fc.value(1532, 1) == 3600  # newest first, seconds


# ------------------------------------------------------- MICROMASTER 4 fault buffer

MM4 = {947: 8, 948: 12, 949: 8, 952: 1, 2114: 2, 2115: 3}  # parameter: elements


def mm4_values(read: Callable[[int, int], int | None]) -> dict[tuple[int, int], int | None]:
    return {(pnu, i): read(pnu, i) for pnu, n in MM4.items() for i in range(n)}


@settings(max_examples=100)
@given(st.lists(st.tuples(st.sampled_from(["fault", "acknowledge"]), st.integers(0, 10**8))))
def test_the_mm4_buffer_reads_as_its_documents_word_it(steps: list[tuple[str, int]]) -> None:
    """Every value of the buffer, after any run the documents word (no third fault in a
    trip, no acknowledgement without one), is what the test's model holds."""
    clock = FakeClock()
    sim = Simulator("uss", [3], seed=5, model=STILL, clock=clock, catalog="siemens-mm4")
    drive, model, ms = sim.drives[3], Mm4Buffer(), 0
    for code, (kind, dt) in enumerate(steps, 1):
        clock.advance(dt / 1000)
        ms += dt
        model.now = ms / 1000
        if kind == "fault" and model.fault(code, code * 7):
            sim.trip(3, code, value=code * 7)
        elif kind == "acknowledge" and model.acknowledge():
            sim.acknowledge(3)
    drive.tick(clock())
    assert mm4_values(drive.value) == mm4_values(lambda pnu, i: model(Read(pnu, i)))


def test_the_mm4_counter_is_kept_over_a_power_cycle_and_stands_still_while_off() -> None:
    clock = FakeClock()
    sim = Simulator("uss", [3], seed=5, model=STILL, clock=clock, catalog="siemens-mm4")
    drive = sim.drives[3]
    clock.advance(70_000)
    sim.trip(3, 3)
    assert [drive.value(948, i) for i in range(3)] == [1, 70_000 - 65_536, 0]
    sim.power_cycle(3, off=600)
    clock.advance(300)
    assert sim.handle(request_telegram(3, pkw.read(USS, 2114, 1), USS)) is None  # off
    clock.advance(400)
    drive.tick(clock())
    assert (drive.value(2114, 0), drive.value(2114, 1)) == (1, 70_100 - 65_536)
    assert drive.value(947, 0) == 3  # kept, still waiting for its acknowledgement
    sim.acknowledge(3)
    drive.set_value(2115, 77, 1)  # the AOP's clock set: the next trip's words are its own
    sim.trip(3, 4)
    assert [drive.value(948, i) for i in range(6)] == [0, 77, 0, 1, 70_000 - 65_536, 0]
