"""The simulated drives describe their parameters (PKW AK 4) in their dialect's form, which
:func:`pkwbus.protocol.pkw.descriptions.read_elements` reads back to the spec's own type,
conversion, unit, name and limits; drives and parameters without a description refuse."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import pytest

from pkwbus.catalog import DEFAULT_CATALOGS
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.descriptions import (
    BASE_UNITS,
    DescriptionForm,
    DriveDescription,
    form_of,
    read_elements,
)
from pkwbus.protocol.pkw.dialects import FC, USS, Dialect, IndLayout, dialect
from pkwbus.protocol.serial.telegram import BlockShape, encode_block, split_block
from pkwbus.protocol.values import ValueType
from pkwbus.sim import ModelConfig, Simulator
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.params import FaultNumbers
from pkwbus.sim.drives.table import TABLES, ParamSpec
from pkwbus.sim.profibus.line import DpSimulator
from tests.sim.conftest import FakeClock, parse, request_telegram

ELEMENTS = (1, 2, 4, 6, 7, 8)
QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)
Ask = Callable[[int, int], pkw.PkwResponse]


def line(protocol: str, *addresses: int, **kw: Any) -> Simulator:
    return Simulator(protocol, addresses, seed=3, model=QUIET, clock=FakeClock(), **kw)


def asker(sim: Simulator, adr: int, pkw_words: int | None = None) -> Ask:
    """Element ``e`` of ``pnu`` asked of drive ``adr`` over the wire (variable PKW block)."""
    d = sim.dialect
    words = 4 if sim.protocol is Bus.FC else pkw_words

    def ask(pnu: int, e: int) -> pkw.PkwResponse:
        telegram = request_telegram(adr, pkw.read_description(d, pnu, e), d, pkw_words=words)
        answer = parse(sim.handle(telegram))
        block = split_block(answer.data, BlockShape(pkw_words, sim.shape.pzd_words))
        return pkw.decode_response(block.pkw, d, sim.layout)

    return ask


def dp_asker(sim: DpSimulator, adr: int) -> Ask:
    """Element ``e`` of ``pnu`` through the slave's PPO (4 fixed PKW words)."""
    drive: SimDrive = sim.drives[adr]
    d, shape = drive.dialect, drive.shape

    def ask(pnu: int, e: int) -> pkw.PkwResponse:
        request = pkw.encode_request(pkw.read_description(d, pnu, e), d, IndLayout.PROFIDRIVE, 4)
        out = drive.respond(encode_block(request, (0,) * shape.pzd_words), 0.0)
        return pkw.decode_response(split_block(out, shape).pkw, d, IndLayout.PROFIDRIVE)

    return ask


def elements(ask: Ask, pnu: int) -> dict[int, pkw.DescriptionResponse | None]:
    found: dict[int, pkw.DescriptionResponse | None] = {}
    for e in ELEMENTS:
        answer = ask(pnu, e)
        assert isinstance(answer, pkw.DescriptionResponse | pkw.Rejection), answer
        found[e] = answer if isinstance(answer, pkw.DescriptionResponse) else None
    return found


def expected_unit(spec: ParamSpec, form: DescriptionForm) -> str | None:
    """The unit a master may take: the spec's when it is a base unit (its scaled value
    is in it), else "no dimension"; none at all without a conversion index. In the FC
    form not Wh, nor degrees C but at conversion 100: the FC 300 Design Guide's unit
    table reads those indexes as J and K."""
    if spec.scale is not None:
        return None
    if form is DescriptionForm.DANFOSS_FC and (
        spec.unit == "Wh" or (spec.unit == "°C" and spec.conversion != 100)
    ):
        return ""
    return spec.unit if spec.unit in BASE_UNITS.values() else ""


def check(spec: ParamSpec, said: DriveDescription, form: DescriptionForm, name: str) -> None:
    assert said.vtype is spec.vtype, spec
    assert said.conversion == (spec.conversion if spec.scale is None else None), spec
    assert said.unit == expected_unit(spec, form), spec
    assert said.name == name, spec
    assert said.array == (spec.array or None), spec
    read_only = not spec.writable or spec.live is not None
    assert said.read_only == (read_only if form is DescriptionForm.PROFIDRIVE else None), spec
    no_limits = spec.vtype is ValueType.TEXT or (
        form is DescriptionForm.DANFOSS_FC and spec.vtype is ValueType.F32
    )
    for limit, got in ((spec.minimum, said.minimum), (spec.maximum, said.maximum)):
        if limit is None or no_limits:
            assert got is None, spec
        else:
            assert got == pytest.approx(limit), spec


@pytest.mark.parametrize("catalog", [None, "default"])
@pytest.mark.parametrize("protocol", ["fc", "uss"])
def test_every_parameter_reads_back_to_its_spec(protocol: str, catalog: str | None) -> None:
    named = DEFAULT_CATALOGS[protocol] if catalog == "default" else None
    sim = line(protocol, 1, catalog=named)
    form = form_of(sim.dialect)
    assert form is (DescriptionForm.DANFOSS_FC if protocol == "fc" else DescriptionForm.PROFIDRIVE)
    ask = asker(sim, 1)
    for spec in sim.drives[1].params.specs.values():
        said = read_elements(form, elements(ask, spec.pnu))
        # FC: the name as long as it is; PROFIdrive: 16 characters.
        name = spec.name if protocol == "fc" else spec.name[:16].strip()
        check(spec, said, form, name)


@pytest.mark.parametrize("name", ["danfoss-pcv", "profidrive"])
def test_dp_slaves_answer_in_the_profidrive_form(name: str) -> None:
    sim = DpSimulator([4], dialect=name, seed=3, model=QUIET)
    ask = dp_asker(sim, 4)
    for spec in sim.drives[4].params.specs.values():
        said = read_elements(DescriptionForm.PROFIDRIVE, elements(ask, spec.pnu))
        check(spec, said, DescriptionForm.PROFIDRIVE, spec.name[:4].strip())  # 4 PKW words


def test_fc_name_of_0_01_byte_for_byte_as_the_design_guide() -> None:
    """Danfoss FC 300 Design Guide, "Read parameter description": the request
    02 0E 01 40 01 00 06 00 00 00 00 .. is answered 02 12 01 30 01 00 06
    4C41 4E47 5541 4745 (LANGUAGE) and PCD1, PCD2, BCC."""
    language = ParamSpec(1, "LANGUAGE", ValueType.U16, writable=True)
    sim = line("fc", 1, specs=(*TABLES[Bus.FC], language))
    request = bytes.fromhex("02 0E 01 40 01 00 06 00 00 00 00 00 00 00 00")
    bcc = 0
    for byte in request:
        bcc ^= byte
    answer = sim.handle(request + bytes([bcc]))
    assert answer is not None
    assert answer[:15] == bytes.fromhex("02 12 01 30 01 00 06 4C41 4E47 5541 4745")
    assert len(answer) == 2 + 0x12


def test_a_unit_that_is_no_base_unit_is_sent_as_no_dimension() -> None:
    """Built-in FC 1-20 is in kW at conversion -2: the scaled value is in kW, not in W
    (size index 9), so the drive sends size index 0; 4-14 in Hz is frequency (28)."""
    sim = line("fc", 1)
    ask = asker(sim, 1)
    motor_power, high_limit = ask(120, 4), ask(414, 4)
    assert isinstance(motor_power, pkw.DescriptionResponse)
    assert isinstance(high_limit, pkw.DescriptionResponse)
    assert motor_power.raw & 0xFFFF == 0xFE00  # conversion -2, no dimension
    assert high_limit.raw & 0xFFFF == 0xFF1C  # conversion -1, size 28 (Hz)


@pytest.mark.parametrize(
    ("unit", "conversion", "fc", "profidrive"),
    [
        ("°C", 100, 0x6411, 0x1164),  # FC: degrees C at conversion 100
        ("°C", 0, 0x0000, 0x1100),  # FC: 17 at 0 is K; MG.33.C4.02: degrees C
        ("Wh", 0, 0x0000, 0x0800),  # FC: 8 at 0 is J; MG.33.C4.02: Wh
        ("J", 0, 0x0000, 0x0000),  # no base unit of MG.33.C4.02
        ("W", 3, 0x0309, 0x0903),  # kW as W at conversion 3, both tables
    ],
)
def test_unit_index_by_each_forms_table(
    unit: str, conversion: int, fc: int, profidrive: int
) -> None:
    """The FC 300 Design Guide's unit index table and MG.33.C4.02's size attribute
    table (6.4.3) differ in two rows; the drive claims neither where they differ."""
    spec = ParamSpec(902, "temperature", ValueType.I16, conversion, unit)
    for protocol, word in (("fc", fc), ("uss", profidrive)):
        sim = line(protocol, 1, specs=(*TABLES[Bus(protocol)], spec))
        answer = asker(sim, 1)(902, 4)
        assert isinstance(answer, pkw.DescriptionResponse) and answer.raw == word, protocol


def test_uss_variable_attribute_and_identifier_bytes() -> None:
    """USS p1120 (f32, s, writable) and r0027 (f32, A, a reading): MG.33.C4.02 byte order."""
    sim = line("uss", 1, catalog=DEFAULT_CATALOGS["uss"])
    ask = asker(sim, 1)
    words = {(pnu, e): ask(pnu, e) for pnu in (1120, 27, 947) for e in (1, 4)}
    raw = {key: r.raw for key, r in words.items() if isinstance(r, pkw.DescriptionResponse)}
    assert raw[1120, 1] == 0x0008 and raw[1120, 4] == 0x0400  # time, conversion 0
    assert raw[27, 1] == 0x0208 and raw[27, 4] == 0x1600  # read-only; current
    assert raw[947, 1] == 0x4206  # array, read-only, Unsigned16


def test_a_parameter_scaled_by_scale_has_bit_8_and_no_variable_attribute() -> None:
    spec = ParamSpec(900, "scaled", ValueType.I16, unit="%", scale=0.5, writable=True)
    for protocol, not_relevant in (("uss", 0x0103), ("fc", 3)):
        sim = line(protocol, 1, specs=(*TABLES[Bus(protocol)], spec))
        ask = asker(sim, 1)
        ident, attribute = ask(900, 1), ask(900, 4)
        assert isinstance(ident, pkw.DescriptionResponse) and ident.raw == not_relevant
        assert isinstance(attribute, pkw.Rejection)
        assert attribute.fault == FaultNumbers.of(sim.dialect).no_description


def test_profidrive_text_length_and_negative_limits() -> None:
    """Element 2 of a text is its length; an Int16 limit of -100 is 32 bit signed."""
    spec = ParamSpec(901, "offset", ValueType.I16, -1, "V", -10.0, 10.0, True)
    sim = line("uss", 1, specs=(*TABLES[Bus.USS], spec))
    ask = asker(sim, 1)
    length, low, high = ask(199, 2), ask(901, 7), ask(901, 8)
    assert isinstance(length, pkw.DescriptionResponse) and length.raw == len(b"PUMP")
    assert isinstance(low, pkw.DescriptionResponse) and low.width is pkw.Width.DWORD
    assert low.raw == 0xFFFFFF9C  # -100 (-10.0 V at conversion -1)
    assert isinstance(high, pkw.DescriptionResponse) and high.raw == 100


def test_a_3_word_uss_block_carries_no_double_word_limit() -> None:
    """A limit is a double word (PROFIdrive): in 3 PKW words the drive answers "channel
    too small"; the name gives its first two characters."""
    sim = line("uss", 1, pkw_words=3)
    ask = asker(sim, 1, pkw_words=3)
    low, name = ask(1120, 7), ask(1120, 6)
    assert isinstance(low, pkw.Rejection) and low.fault == FaultNumbers.of(USS).channel
    assert isinstance(name, pkw.DescriptionResponse) and name.data == b"p1"


# --------------------------------------------------------------- refusing drives


def refused(answer: pkw.PkwResponse, d: Dialect) -> bool:
    return isinstance(answer, pkw.Rejection) and answer.fault == FaultNumbers.of(d).no_description


@pytest.mark.parametrize(("protocol", "pnu"), [("fc", 341), ("uss", 1120)])
def test_a_drive_that_refuses_descriptions(protocol: str, pnu: int) -> None:
    sim = line(protocol, 1, 2, refuse_descriptions=[2])
    d = sim.dialect
    assert all(refused(asker(sim, 2)(pnu, e), d) for e in ELEMENTS)
    assert not any(refused(asker(sim, 1)(pnu, e), d) for e in (1, 2, 4, 6))
    # The refusing drive still answers its values.
    telegram = request_telegram(2, pkw.read(d, pnu), d, pkw_words=4 if protocol == "fc" else None)
    block = split_block(parse(sim.handle(telegram)).data, BlockShape(None, sim.shape.pzd_words))
    assert isinstance(pkw.decode_response(block.pkw, d, sim.layout), pkw.ValueResponse)


def test_fc_refusal_is_description_not_available() -> None:
    """The Danfoss fault number 9, "description not available" in the FC dialect table."""
    answer = asker(line("fc", 1, refuse_descriptions=[1]), 1)(341, 1)
    assert isinstance(answer, pkw.Rejection) and answer.fault == 9
    assert answer.short == FC.fault(9).short == "description not available"


def test_dp_slaves_that_refuse_descriptions() -> None:
    sim = DpSimulator([4, 5], dialect="danfoss-pcv", seed=3, model=QUIET, refuse_descriptions=[5])
    d = dialect("danfoss-pcv")
    assert refused(dp_asker(sim, 5)(341, 1), d)
    assert not refused(dp_asker(sim, 4)(341, 1), d)


def test_a_parameter_without_description() -> None:
    specs = tuple(
        dataclasses.replace(s, described=False) if s.pnu == 341 else s for s in TABLES[Bus.FC]
    )
    ask = asker(line("fc", 1, specs=specs), 1)
    assert all(refused(ask(341, e), FC) for e in ELEMENTS)
    assert isinstance(ask(342, 1), pkw.DescriptionResponse)


def test_refusing_an_address_that_is_no_drive_is_an_error() -> None:
    with pytest.raises(ValueError, match="no simulated drive at address 7"):
        line("fc", 1, refuse_descriptions=[7])
    with pytest.raises(ValueError, match="no simulated drive at address 9"):
        DpSimulator([4], refuse_descriptions=[9])
