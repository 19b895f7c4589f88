"""What a simulated drive remembers, its settings: the factory setting (FC description
element 20), the additional characteristics (FC element 21), the PROFIdrive identifier's
"changed from factory setting" bit, values set at the keypad with no telegram, and random
keypad changes for the demo (``keypad_every``)."""

from __future__ import annotations

import logging
import random
import struct
from typing import Any

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw import Width
from pkwbus.protocol.pkw.dialects import FC, USS, IndLayout
from pkwbus.protocol.serial.telegram import BlockShape, encode_block, split_block
from pkwbus.protocol.values import ValueType, encode_value
from pkwbus.sim import ModelConfig, Simulator
from pkwbus.sim.drives.keypad import nudged
from pkwbus.sim.drives.params import FaultNumbers
from pkwbus.sim.drives.table import TABLES, ParamSpec
from pkwbus.sim.profibus.line import DpSimulator
from pkwbus.sim.serving.url import SimPort, parse_sim_port
from tests.sim.conftest import FakeClock, parse, request_telegram
from tests.sim.test_dp_line import Wire

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)
LCP_READ_ONLY, LCP_READ_WRITE = 1 << 7, 1 << 8
STD_BUS_READ_ONLY, PROFIBUS_READ_ONLY = 1 << 10, 1 << 11
CHANGE_RUNNING, POWER_UNIT = 1 << 13, 1 << 15
CHANGED = 1 << 12  # PROFIdrive identifier: "parameter has been changed from factory setting"


def line(protocol: str, *addresses: int, clock: FakeClock | None = None, **kw: Any) -> Simulator:
    return Simulator(protocol, addresses, seed=3, model=QUIET, clock=clock or FakeClock(), **kw)


def ask(sim: Simulator, adr: int, req: pkw.PkwRequest) -> pkw.PkwResponse:
    """``req`` to drive ``adr`` over the wire; its answer as a master decodes it."""
    words = 4 if sim.protocol is Bus.FC else None
    answer = parse(sim.handle(request_telegram(adr, req, sim.dialect, pkw_words=words)))
    block = split_block(answer.data, BlockShape(None, sim.shape.pzd_words))
    return pkw.decode_response(block.pkw, sim.dialect, sim.layout)


def element(sim: Simulator, adr: int, pnu: int, number: int) -> pkw.DescriptionResponse:
    answer = ask(sim, adr, pkw.read_description(sim.dialect, pnu, number))
    assert isinstance(answer, pkw.DescriptionResponse), answer
    return answer


def value(sim: Simulator, adr: int, pnu: int) -> int:
    answer = ask(sim, adr, pkw.read(sim.dialect, pnu))
    assert isinstance(answer, pkw.ValueResponse), answer
    return answer.raw


def f32(number: float) -> int:
    return int.from_bytes(struct.pack(">f", number), "big")


def stop(sim: Simulator, adr: int, clock: FakeClock) -> None:
    """The motor is stopped and has ramped down (as test_answers stops it)."""
    sim.drives[adr].model.running = False
    clock.advance(60)
    sim.drives[adr].tick(clock())
    assert not sim.drives[adr].running


# ------------------------------------------------------- FC element 20, factory setting


def test_fc_element_20_is_each_parameters_initial_value_in_its_own_type() -> None:
    sim = line("fc", 1)
    numbers = [
        s for s in TABLES[Bus.FC] if s.vtype not in (ValueType.TEXT, ValueType.F32) and not s.array
    ]
    assert len(numbers) > 10
    for spec in numbers:
        said = element(sim, 1, spec.pnu, 20)
        assert isinstance(spec.initial, float | int)
        assert said.raw == encode_value(float(spec.initial), spec.vtype, spec.scaling), spec
    assert element(sim, 1, 341, 20).raw == 500  # 5.00 s, Uint32 at conversion -2
    assert element(sim, 1, 414, 20).raw == 500  # 50.0 Hz, Uint16 at conversion -1


def test_fc_element_20_stays_the_factory_value_after_a_write() -> None:
    sim = line("fc", 1)
    written = ask(sim, 1, pkw.write(FC, 341, 1234, Width.DWORD, store=pkw.Store.EEPROM))
    assert isinstance(written, pkw.ValueResponse) and written.raw == 1234
    assert value(sim, 1, 341) == 1234
    assert element(sim, 1, 341, 20).raw == 500


def test_fc_element_20_of_a_text_is_not_available() -> None:
    answer = ask(line("fc", 1), 1, pkw.read_description(FC, 1540, 20))
    assert isinstance(answer, pkw.Rejection) and answer.fault == FaultNumbers.of(FC).no_description


# ------------------------------------------- FC element 21, additional characteristics


def test_fc_element_21_of_a_writable_a_read_only_and_a_motor_data_parameter() -> None:
    sim = line("fc", 1)
    ramp, frequency, motor_power = (element(sim, 1, pnu, 21) for pnu in (341, 1613, 120))
    assert ramp.raw == LCP_READ_WRITE
    assert frequency.raw == LCP_READ_ONLY | STD_BUS_READ_ONLY | PROFIBUS_READ_ONLY
    assert motor_power.raw == LCP_READ_WRITE | CHANGE_RUNNING | POWER_UNIT
    text = element(sim, 1, 1540, 21)  # a read-only text
    assert text.raw == LCP_READ_ONLY | STD_BUS_READ_ONLY | PROFIBUS_READ_ONLY


def test_the_catalogs_other_fc_motor_data_say_bits_13_and_15() -> None:
    sim = line("fc", 1, catalog="danfoss-fc")
    assert 122 in sim.drives[1].params.specs  # 1-22 Motor Voltage, only the catalog has it
    said = element(sim, 1, 122, 21).raw
    assert said & CHANGE_RUNNING and said & POWER_UNIT
    assert not element(sim, 1, 341, 21).raw & (CHANGE_RUNNING | POWER_UNIT)


def test_a_bit_13_parameter_is_refused_with_17_while_running_and_taken_when_stopped() -> None:
    clock = FakeClock()
    sim = line("fc", 1, clock=clock)
    assert element(sim, 1, 120, 21).raw & CHANGE_RUNNING
    assert sim.drives[1].running
    refused = ask(sim, 1, pkw.write(FC, 120, 1100, Width.DWORD))
    assert isinstance(refused, pkw.Rejection) and refused.fault == 17
    assert value(sim, 1, 120) == 1500
    stop(sim, 1, clock)
    taken = ask(sim, 1, pkw.write(FC, 120, 1100, Width.DWORD))
    assert isinstance(taken, pkw.ValueResponse) and taken.raw == 1100
    assert value(sim, 1, 120) == 1100


# ------------------------------------------------- PROFIdrive identifier, bit 12


def test_profidrive_identifier_bit_12_follows_the_value_against_the_factory_setting() -> None:
    sim = line("uss", 1)
    assert not element(sim, 1, 1120, 1).raw & CHANGED
    changed = ask(sim, 1, pkw.write(USS, 1120, f32(20.0), Width.DWORD))
    assert isinstance(changed, pkw.ValueResponse)
    ident = element(sim, 1, 1120, 1).raw
    assert ident & CHANGED and ident & 0xFF == 8  # still FloatingPoint
    assert not element(sim, 1, 1121, 1).raw & CHANGED  # the other ramp is untouched
    back = ask(sim, 1, pkw.write(USS, 1120, f32(10.0), Width.DWORD))
    assert isinstance(back, pkw.ValueResponse)
    assert not element(sim, 1, 1120, 1).raw & CHANGED


def test_profidrive_text_and_live_values_and_no_element_20() -> None:
    sim = line("uss", 1)
    assert not element(sim, 1, 199, 1).raw & CHANGED
    written = ask(sim, 1, pkw.write_text(USS, 199, b"FAN-12"))
    assert isinstance(written, pkw.TextResponse)
    assert element(sim, 1, 199, 1).raw & CHANGED
    assert not element(sim, 1, 21, 1).raw & CHANGED  # a reading is no setting
    for number in (20, 21):
        answer = ask(sim, 1, pkw.read_description(USS, 1120, number))
        assert isinstance(answer, pkw.Rejection), number
        assert answer.fault == FaultNumbers.of(USS).no_description


# ---------------------------------------------------------------------- the keypad


def test_a_keypad_change_is_read_over_the_bus_and_kept_in_eeprom() -> None:
    sim = line("fc", 1, 2)
    sim.keypad(1, 341, 750)
    assert value(sim, 1, 341) == 750
    assert sim.drives[1].eeprom[341, 0] == 750
    assert value(sim, 2, 341) == 500  # the other drive's keypad is untouched
    assert element(sim, 1, 341, 20).raw == 500  # the factory setting stays
    assert sim.drives[1].keypad_changes == 1


def test_a_keypad_change_sets_the_profidrive_changed_bit_and_steers_the_model() -> None:
    clock = FakeClock()
    sim = line("uss", 1, clock=clock)
    drive = sim.drives[1]
    sim.keypad(1, 1121, f32(50.0))  # ramp down time 10 s -> 50 s
    assert value(sim, 1, 1121) == f32(50.0)
    assert element(sim, 1, 1121, 1).raw & CHANGED
    drive.model.running = False
    clock.advance(1.0)
    drive.tick(clock())
    assert drive.model.frequency == pytest.approx(40.0 - 1.0)  # 50 Hz in 50 s: 1 Hz a second


def test_a_keypad_change_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    sim = line("fc", 3)
    with caplog.at_level(logging.INFO, logger="pkwbus.sim"):
        sim.keypad(3, 342, 800)
    (record,) = [r for r in caplog.records if "keypad" in r.getMessage()]
    assert record.getMessage() == "drive 3: 3-42 (PNU 342) set at the keypad from 5 s to 8 s"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((9, 341, 750), "no simulated drive at address 9"),
        ((1, 999, 1), "no parameter 999"),
        ((1, 1613, 100), "parameter 1613 .* is read-only"),
        ((1, 341, 400_000), "outside its limits 0.01..3600 s"),
        ((1, 341, 0), "outside its limits"),
        ((1, 341, 1 << 32), "does not fit 32 bits"),
        ((1, 341, 750, 1), "no index 1"),
        ((1, 120, 1100), "cannot be changed while the motor runs"),
        ((1, 1540, 0), "is read-only"),
    ],
)
def test_the_keypad_refuses_bad_input_plainly(args: tuple[int, ...], message: str) -> None:
    sim = line("fc", 1)
    with pytest.raises(ValueError, match=message):
        sim.keypad(*args)
    assert value(sim, 1, 341) == 500 and sim.drives[1].keypad_changes == 0


def test_the_keypad_refuses_a_text_and_a_float_outside_its_limits() -> None:
    sim = line("uss", 1)
    with pytest.raises(ValueError, match="is a text"):
        sim.keypad(1, 199, 0)
    with pytest.raises(ValueError, match="outside its limits"):
        sim.keypad(1, 1120, f32(651.0))
    with pytest.raises(ValueError, match="not a number"):
        sim.keypad(1, 1120, 0x7FC00000)  # NaN


def test_motor_data_is_taken_at_the_keypad_when_stopped() -> None:
    clock = FakeClock()
    sim = line("fc", 1, clock=clock)
    stop(sim, 1, clock)
    sim.keypad(1, 120, 750)
    assert value(sim, 1, 120) == 750


def dp_read(sim: DpSimulator, adr: int, req: pkw.PkwRequest) -> pkw.PkwResponse:
    """``req`` through the slave's PPO (4 PKW words), as tests/sim/test_descriptions does."""
    drive = sim.drives[adr]
    d, shape = drive.dialect, drive.shape
    request = pkw.encode_request(req, d, IndLayout.PROFIDRIVE, 4)
    out = drive.respond(encode_block(request, (0,) * shape.pzd_words), 0.0)
    return pkw.decode_response(split_block(out, shape).pkw, d, IndLayout.PROFIDRIVE)


def test_a_dp_slaves_drive_has_a_keypad_too() -> None:
    sim = DpSimulator([4], dialect="danfoss-pcv", seed=3, model=QUIET, clock=FakeClock())
    d = sim.drives[4].dialect
    before = dp_read(sim, 4, pkw.read_description(d, 341, 1))
    assert isinstance(before, pkw.DescriptionResponse) and not before.raw & CHANGED
    sim.keypad(4, 341, 900)
    read = dp_read(sim, 4, pkw.read(d, 341))
    assert isinstance(read, pkw.ValueResponse) and read.raw == 900
    after = dp_read(sim, 4, pkw.read_description(d, 341, 1))
    assert isinstance(after, pkw.DescriptionResponse) and after.raw & CHANGED
    with pytest.raises(ValueError, match="no simulated slave at address 5"):
        sim.keypad(5, 341, 900)
    with pytest.raises(ValueError, match="outside its limits"):
        sim.keypad(4, 341, 400_000)  # 4000 s


# ------------------------------------------------------------ random keypad changes


def test_keypad_every_on_the_sim_port() -> None:
    assert parse_sim_port("sim://fc?drives=1,2&keypad_every=10m") == SimPort(
        Bus.FC, (1, 2), None, (), 600.0
    )
    assert parse_sim_port("sim://uss?drives=1&keypad_every=90").keypad_every == 90.0
    assert parse_sim_port("sim://uss?drives=1&keypad_every=1h&response_delay=2ms") == SimPort(
        Bus.USS, (1,), 0.002, (), 3600.0
    )
    assert parse_sim_port("sim://fc?drives=1").keypad_every is None


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("keypad_every=soon", "keypad_every 'soon' is not a duration"),
        ("keypad_every=", "is not a duration"),
        ("keypad_every=0", "keypad_every .0. is not a duration above 0"),
        ("keypad_every=-5m", "not a duration above 0"),
        ("keypad_every=500ms", "too short for a keypad change interval"),
        ("keypad_every=200h", "too long for a keypad change interval"),
        ("keypad_every=10m&keypad_every=5m", "given twice"),
    ],
)
def test_bad_keypad_every_is_refused_plainly(option: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_sim_port(f"sim://fc?drives=1&{option}")


def test_keypad_every_must_be_above_0_for_the_simulators() -> None:
    with pytest.raises(ValueError, match="give a time above 0"):
        line("fc", 1, keypad_every=0.0)
    with pytest.raises(ValueError, match="give a time above 0"):
        DpSimulator([4], keypad_every=-1.0)


def poll(sim: Simulator, clock: FakeClock, seconds: int, adr: int = 1) -> None:
    """A master reading 16-13 of drive ``adr`` once a second for ``seconds``."""
    for _ in range(seconds):
        clock.advance(1.0)
        ask(sim, adr, pkw.read(sim.dialect, 1613 if sim.protocol is Bus.FC else 21))


def settings(sim: Simulator, adr: int) -> dict[int, int]:
    params = sim.drives[adr].params
    return {pnu: raw for (pnu, _), raw in params.raw.items()}


def test_random_keypad_changes_come_about_once_per_keypad_every(
    caplog: pytest.LogCaptureFixture,
) -> None:
    clock = FakeClock()
    sim = line("fc", 1, 2, clock=clock, keypad_every=60.0)
    factory = settings(sim, 1), settings(sim, 2)
    with caplog.at_level(logging.INFO, logger="pkwbus.sim"):
        poll(sim, clock, 3600)
    changes = sum(d.keypad_changes for d in sim.drives.values())
    assert 35 <= changes <= 90  # 60 expected in an hour, over the line
    assert all(d.keypad_changes > 0 for d in sim.drives.values())
    logged = [r for r in caplog.records if "set at the keypad" in r.getMessage()]
    assert len(logged) == changes
    for adr, before in zip((1, 2), factory, strict=True):
        now = settings(sim, adr)
        moved = {pnu for pnu in before if now[pnu] != before[pnu]}
        assert moved and moved <= {341, 342, 414}  # settings; 1-20 not while running
        for pnu in moved:
            spec = sim.drives[adr].params.specs[pnu]
            number = sim.drives[adr].params.number(pnu)
            assert spec.minimum is not None and spec.maximum is not None
            assert spec.minimum <= number <= spec.maximum
        assert value(sim, adr, 341) == now[341]  # read over the bus as set


def test_no_random_keypad_changes_without_the_option_or_time() -> None:
    clock = FakeClock()
    quiet = line("fc", 1, clock=clock)
    poll(quiet, clock, 600)
    assert quiet.drives[1].keypad_changes == 0
    frozen = line("fc", 1, clock=FakeClock(), keypad_every=1.0)
    for _ in range(200):
        ask(frozen, 1, pkw.read(FC, 1613))  # the clock stands still: no time for a change
    assert frozen.drives[1].keypad_changes == 0


def test_random_keypad_changes_spare_a_dead_drive_and_are_the_same_for_a_seed() -> None:
    runs = []
    for _ in range(2):
        clock = FakeClock()
        sim = line("uss", 1, 2, clock=clock, keypad_every=30.0)
        sim.kill(2)
        poll(sim, clock, 1800)
        assert sim.drives[1].keypad_changes > 20
        assert sim.drives[2].keypad_changes == 0
        runs.append(settings(sim, 1))
    assert runs[0] == runs[1]


def test_random_keypad_changes_on_a_dp_line() -> None:
    clock = FakeClock(0.0)
    sim = DpSimulator(
        [9], dialect="danfoss-pcv", seed=2, model=QUIET, clock=clock, keypad_every=20.0
    )
    wire = Wire(sim, 9)
    for _ in range(600):
        clock.advance(1.0)
        wire.cycle(clock())
    assert sim.drives[9].keypad_changes > 10


def test_a_nudge_stays_within_the_limits_and_moves() -> None:
    rng = random.Random(1)
    ramp = ParamSpec(341, "3-41", ValueType.U32, -2, "s", 0.01, 3600.0, True, initial=5.0)
    high = encode_value(3600.0, ramp.vtype, ramp.scaling)
    low = encode_value(0.01, ramp.vtype, ramp.scaling)
    for raw in (low, 500, high):
        for _ in range(200):
            found = nudged(ramp, raw, 500, rng)
            assert found is not None and found != raw and low <= found <= high
    fixed = ParamSpec(9, "fixed", ValueType.U16, 0, "", 5.0, 5.0, True, initial=5.0)
    assert nudged(fixed, 5, 5, rng) is None
