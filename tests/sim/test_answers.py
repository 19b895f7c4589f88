"""The simulator answers as a drive does: section 7 telegrams, values, faults, addressing."""

from __future__ import annotations

import struct

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw import Rejection, TextResponse, ValueResponse, Width
from pkwbus.protocol.pkw.dialects import FC, USS, IndLayout
from pkwbus.protocol.pzd import Profile, status_bits
from pkwbus.protocol.serial.telegram import (
    BlockShape,
    FcAddressFormat,
    encode_block,
    fc_adr,
    frame,
    split_block,
    uss_adr,
)
from pkwbus.sim import ModelConfig, SimDrive, Simulator
from tests.sim.conftest import FakeClock, parse, request_telegram

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)
FC_PARAM = BlockShape(None, 2)


def fc_sim(*addresses: int, clock: FakeClock | None = None) -> Simulator:
    return Simulator("fc", addresses, seed=7, model=QUIET, clock=clock or FakeClock())


def fc_answer(sim: Simulator, adr: int, req: pkw.PkwRequest) -> pkw.PkwResponse:
    answer = parse(sim.handle(request_telegram(adr, req, FC)))
    assert answer.adr == adr
    block = split_block(answer.data, FC_PARAM)
    return pkw.decode_response(block.pkw, FC, IndLayout.USS)


def expected_fc(drive: SimDrive, adr: int, pkw_bytes: bytes) -> bytes:
    return frame(adr, encode_block(pkw_bytes, (drive.status_word, drive.mav)))


# ------------------------------------------------------- protocol.md section 7


def test_section7_read_16_14_byte_for_byte() -> None:
    sim = fc_sim(1)
    drive = sim.drives[1]
    request = bytes.fromhex("02 0E 01 16 4E 00 00 00 00 00 00 00 00 00 00 55")
    answer = sim.handle(request)
    current = drive.value(1614)
    assert current > 0  # the motor runs: current flows
    resp = ValueResponse(2, 1614, 0, current, Width.DWORD)  # 16-14 is 32 bit: AK 2
    assert answer == expected_fc(drive, 0x01, pkw.encode_response(resp, FC, IndLayout.USS, 4))


def test_section7_write_4_14_to_eeprom_byte_for_byte() -> None:
    sim = fc_sim(1)
    drive = sim.drives[1]
    request = bytes.fromhex("02 0E 01 E1 9E 00 00 00 00 03 E8 00 00 00 00 99")
    answer = sim.handle(request)
    resp = ValueResponse(1, 414, 0, 1000, Width.WORD)
    assert answer == expected_fc(drive, 0x01, pkw.encode_response(resp, FC, IndLayout.USS, 4))
    assert drive.value(414) == 1000
    assert drive.eeprom[414, 0] == 1000


def test_section7_read_3_41() -> None:
    sim = fc_sim(1)
    drive = sim.drives[1]
    answer = sim.handle(bytes.fromhex("02 0E 01 11 55 00 00 00 00 00 00 00 00 00 00 49"))
    resp = ValueResponse(2, 341, 0, 500, Width.DWORD)  # 5.00 s, conversion -2
    assert answer == expected_fc(drive, 0x01, pkw.encode_response(resp, FC, IndLayout.USS, 4))


def test_section7_process_only_at_address_4_in_1_31_format() -> None:
    sim = fc_sim(4)
    drive = sim.drives[4]
    answer = sim.handle(bytes.fromhex("02 06 04 04 7C 20 00 58"))
    assert answer is not None and len(answer) == 8 and answer[2] == 0x04
    assert answer == frame(0x04, encode_block(b"", (drive.status_word, drive.mav)))
    bits = status_bits(drive.status_word, Profile.FC)
    assert bits["bus_control"] and bits["running"]  # CTW 0x047C has bit 10: it took control
    assert drive.control_taken == 1
    assert sim.stats.as_dict()["control_taken"] == 1


def test_section7_uss_3_word_read_of_an_unknown_parameter() -> None:
    sim = Simulator("uss", [3], pkw_words=3, seed=1, model=QUIET, clock=FakeClock())
    answer = parse(sim.handle(bytes.fromhex("02 0C 03 10 66 00 01 00 00 00 00 00 00 7A")))
    assert answer.adr == 3
    block = split_block(answer.data, BlockShape(3, 2))
    resp = pkw.decode_response(block.pkw, USS, IndLayout.USS)
    assert isinstance(resp, Rejection) and (resp.pnu, resp.subindex, resp.fault) == (0x66, 1, 0)


def test_section7_uss_broadcast_gets_no_answer_but_is_applied() -> None:
    sim = Simulator("uss", [1, 2], pkw_words=3, seed=1, model=QUIET, clock=FakeClock())
    # USS addr 0 is a drive address; make it a broadcast by setting bit 5.
    tg = frame(uss_adr(0, broadcast=True), bytes(6) + b"\x04\x7e\x00\x00")
    assert sim.handle(tg) is None
    assert sim.stats.as_dict()["broadcasts"] == 1
    assert all(d.control_taken == 1 for d in sim.drives.values())


# ---------------------------------------------------------------- the model


def test_fc_parameter_faults() -> None:
    sim = fc_sim(1)
    cases = [
        (pkw.read(FC, 999), 0),  # unknown number
        (pkw.write(FC, 1613, 100, Width.WORD), 1),  # read-only
        (pkw.write(FC, 341, 0, Width.DWORD), 2),  # below 0.01 s
        (pkw.write(FC, 341, 400_000, Width.DWORD), 2),  # above 3600 s
        (pkw.write(FC, 120, 1100, Width.DWORD), 17),  # motor power while running (0x11)
        (pkw.write(FC, 341, 100, Width.WORD), 5),  # word to a double word parameter
        (pkw.read(FC, 1530, 10), 3),  # alarm log has 10 elements
        (pkw.read(FC, 1613, 2), 4),  # not an array
        (pkw.read_text(FC, 1613), 15),
    ]
    for req, fault in cases:
        resp = fc_answer(sim, 1, req)
        assert isinstance(resp, Rejection), req
        assert resp.fault == fault, req
        assert resp.ak == 7


def test_write_in_ram_changes_the_model_and_not_the_eeprom() -> None:
    clock = FakeClock()
    sim = fc_sim(1, clock=clock)
    drive = sim.drives[1]
    resp = fc_answer(sim, 1, pkw.write(FC, 342, 1000, Width.DWORD))
    assert isinstance(resp, ValueResponse) and resp.raw == 1000 and resp.ak == 2
    assert drive.value(342) == 1000 and (342, 0) not in drive.eeprom
    drive.model.running = False
    clock.advance(1.0)  # 10 s ramp down from 50 Hz: 5 Hz a second
    drive.tick(clock())
    assert drive.value(1613) == 350  # 40.0 Hz - 5.0 Hz, conversion -1


def test_stopped_drive_accepts_motor_power_and_shows_in_status() -> None:
    clock = FakeClock()
    sim = fc_sim(1, clock=clock)
    drive = sim.drives[1]
    drive.model.running = False
    clock.advance(60)
    resp = fc_answer(sim, 1, pkw.write(FC, 120, 750, Width.DWORD, store=pkw.Store.EEPROM))
    assert isinstance(resp, ValueResponse) and resp.raw == 750
    assert drive.eeprom[120, 0] == 750
    bits = status_bits(drive.status_word, Profile.FC)
    assert not bits["running"] and not bits["trip"]
    assert drive.mav == 0


def test_energy_grows_and_trip_fills_the_alarm_log() -> None:
    clock = FakeClock()
    sim = fc_sim(1, clock=clock)
    drive = sim.drives[1]
    clock.advance(3600)
    drive.tick(clock())
    # 11 kW at full speed, cube law at 80 %: 5.632 kWh in an hour, shown as 6
    assert drive.value(1502) == round(11 * 0.8**3)
    assert drive.value(1500) == 1
    drive.model.trip(13, 3)
    assert drive.tripped and drive.value(1530, 0) == 13 and drive.value(1690) == 1 << 3
    resp = fc_answer(sim, 1, pkw.read(FC, 1530, 0))
    assert isinstance(resp, ValueResponse) and resp.raw == 13
    assert status_bits(drive.status_word, Profile.FC)["trip"]


def test_text_parameter() -> None:
    sim = fc_sim(1)
    resp = fc_answer(sim, 1, pkw.read_text(FC, 1540))
    assert isinstance(resp, TextResponse) and resp.text == b"FC-102"


def test_uss_float_read_and_page_index() -> None:
    sim = Simulator("uss", [2], seed=3, model=QUIET, clock=FakeClock())
    drive = sim.drives[2]
    req = pkw.read(USS, 2000)  # p2000 needs page index 0x80
    answer = parse(sim.handle(request_telegram(2, req, USS)))
    block = split_block(answer.data, BlockShape(4, 2))
    resp = pkw.decode_response(block.pkw, USS, IndLayout.USS)
    assert isinstance(resp, ValueResponse) and resp.pnu == 2000 and resp.ak == 2
    assert struct.unpack(">f", resp.raw.to_bytes(4, "big"))[0] == 50.0
    assert block.pzd == (drive.status_word, drive.mav)
    assert drive.mav == 0x3333  # 40 Hz of 50 Hz = 80 %
    status = status_bits(drive.status_word, Profile.PROFIDRIVE)
    assert status["operation_enabled"] and status["reference_reached"]


def test_uss_array_read_is_answered_with_ak_4_and_p0304_is_17_while_running() -> None:
    sim = Simulator("uss", [2], seed=3, model=QUIET, clock=FakeClock(), pkw_words=4)
    sim.drives[2].model.trip(2, 1)
    ans = parse(sim.handle(request_telegram(2, pkw.read(USS, 947, 0), USS)))
    resp = pkw.decode_response(ans.data[:8], USS, IndLayout.USS)
    assert isinstance(resp, ValueResponse) and (resp.ak, resp.raw) == (4, 2)
    sim.drives[2].model.reset()
    write = pkw.write(USS, 304, 230, Width.WORD)
    ans = parse(sim.handle(request_telegram(2, write, USS)))
    resp = pkw.decode_response(ans.data[:8], USS, IndLayout.USS)
    assert isinstance(resp, Rejection) and resp.fault == 17


def test_uss_shape_mismatch_gets_no_answer() -> None:
    sim = Simulator("uss", [2], pkw_words=4, seed=3, clock=FakeClock())
    assert sim.handle(request_telegram(2, pkw.read(USS, 21), USS, pkw_words=3)) is None


# --------------------------------------------------------------- addressing


def test_answers_only_its_own_address_and_echoes_adr() -> None:
    sim = fc_sim(1, 5)
    req = pkw.read(FC, 1613)
    assert sim.handle(request_telegram(fc_adr(2), req, FC)) is None
    for adr in (fc_adr(5), fc_adr(5, FcAddressFormat.RANGE_1_31)):
        assert parse(sim.handle(request_telegram(adr, req, FC))).adr == adr
    stats = sim.stats.as_dict()
    assert stats["ignored"] == 1 and stats["per_drive"]["5"]["requests"] == 2


@pytest.mark.parametrize("fmt", list(FcAddressFormat))
def test_fc_broadcast_applies_a_write_and_gets_no_answer(fmt: FcAddressFormat) -> None:
    sim = fc_sim(1, 2)
    req = pkw.write(FC, 342, 777, Width.DWORD)
    assert sim.handle(request_telegram(fc_adr(0, fmt, broadcast=True), req, FC)) is None
    assert [d.value(342) for d in sim.drives.values()] == [777, 777]
    assert sim.stats.as_dict()["responses"] == 0


def test_uss_mirror_telegram_comes_back_unchanged() -> None:
    sim = Simulator("uss", [3], seed=1, clock=FakeClock())
    tg = frame(uss_adr(3, mirror=True), bytes(range(12)))
    assert sim.handle(tg) == tg
    assert sim.handle(frame(uss_adr(4, mirror=True), bytes(12))) is None


def test_control_taken_counts_ctw_bit_10() -> None:
    sim = Simulator("uss", [1], seed=1, model=QUIET, clock=FakeClock())
    for ctw in (0x0000, 0x047E, 0x047F, 0x007F, 0x0400):
        sim.handle(request_telegram(1, pkw.none_request(USS), USS, pzd=(ctw, 0)))
    drive = sim.drives[1]
    assert drive.control_taken == 3
    assert list(drive.ctw_log) == [False, True, True, False, True]
    assert drive.requests_seen == 5


def test_monitoring_master_never_changes_the_motor() -> None:
    sim = Simulator("uss", [1], seed=1, model=QUIET, clock=FakeClock())
    drive = sim.drives[1]
    before = drive.model.setpoint
    sim.handle(request_telegram(1, pkw.read(USS, 21), USS, pzd=(0x007F, 0x1000)))
    assert drive.model.setpoint == before and drive.control_taken == 0
    sim.handle(request_telegram(1, pkw.read(USS, 21), USS, pzd=(0x047F, 0x2000)))
    assert drive.model.setpoint == 25.0 and drive.control_taken == 1
