"""Description elements (PKW AK 4) read in the Danfoss FC and the PROFIdrive form, against
the vendor documents: the Danfoss FC 300 Design Guide (MG.33.B3.22), "Read parameter
description", and the Danfoss VLT PROFIBUS manual MG.33.C4.02, section 5 "Parameter
description" and 6.4.3 "Size attribute"."""

from __future__ import annotations

import struct

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import (
    Characteristics,
    DescriptionForm,
    DriveDescription,
    changed_from_factory,
    elements_to_read,
    factory_raw,
    form_of,
    read_elements,
)
from pkwbus.protocol.pkw.dialects import (
    DANFOSS_PCV,
    FC,
    HITACHI_SJPB,
    PROFIDRIVE,
    USS,
    Dialect,
    Reply,
)
from pkwbus.protocol.serial.telegram import encode_block, frame
from pkwbus.protocol.values import ValueType

FC_FORM = DescriptionForm.DANFOSS_FC
PROFIDRIVE_FORM = DescriptionForm.PROFIDRIVE
WORD, DWORD = pkw.Width.WORD, pkw.Width.DWORD


def element(
    number: int, raw: int, width: pkw.Width = WORD, dialect: Dialect = PROFIDRIVE
) -> pkw.DescriptionResponse:
    """An answer to element ``number`` as a drive of ``dialect`` sends it."""
    data = raw.to_bytes(2 if width is WORD else 4, "big")
    ak = pkw.response_id(dialect, Reply.DESCRIPTION)
    return pkw.DescriptionResponse(ak, 1, number, raw, data, width)


def read(form: DescriptionForm, **elements: pkw.DescriptionResponse) -> DriveDescription:
    return read_elements(form, {int(key[1:]): value for key, value in elements.items()})


# ------------------------------------------ FC 300 Design Guide, "Read parameter description"


def test_fc_guide_request_for_the_name_of_0_01() -> None:
    """The guide's telegram: STX 02, LGE 0E, ADR 01, PKE 4001, IND 0006, PWE 0000 0000."""
    req = pkw.read_description(FC, 1, 6)
    data = pkw.encode_request(req, FC, FC.default_ind_layout, 4)
    assert data == bytes.fromhex("4001 0006 0000 0000")
    telegram = frame(0x01, encode_block(data, (0, 0)))
    assert telegram[:11] == bytes.fromhex("02 0E 01 40 01 00 06 00 00 00 00")


def test_fc_guide_answer_with_the_name_language() -> None:
    """The guide's answer: PKE 3001, IND 0006, PVA 4C41 4E47 5541 4745 "LANGUAGE"."""
    answer = pkw.decode_response(
        bytes.fromhex("3001 0006 4C41 4E47 5541 4745"), FC, FC.default_ind_layout
    )
    assert isinstance(answer, pkw.DescriptionResponse)
    assert (answer.ak, answer.pnu, answer.subindex) == (3, 1, 6)
    assert read_elements(FC_FORM, {6: answer}).name == "LANGUAGE"


def test_fc_guide_basic_characteristics_of_0_01() -> None:
    """The guide's answer PWE low 0405: bit 10 "additional text", data type 5 Unsigned 8."""
    answer = pkw.decode_response(bytes.fromhex("3001 0001 0000 0405"), FC, FC.default_ind_layout)
    assert isinstance(answer, pkw.DescriptionResponse)
    said = read_elements(FC_FORM, {1: answer})
    assert (said.type_code, said.type_name) == (5, "UInt8")
    assert said.read_only is None  # the FC form has no read-only bit


def test_fc_guide_conversion_in_the_high_byte_unit_in_the_low() -> None:
    """The guide's example: unit index 9 (power), conversion index 2; raw 23 is 2300 W."""
    said = read(FC_FORM, e1=element(1, 6, dialect=FC), e4=element(4, 0x0209, dialect=FC),
                e7=element(7, 23, dialect=FC))  # fmt: skip
    assert (said.conversion, said.unit) == (2, "W")
    assert said.minimum == 2300.0


def test_fc_signed_conversion_index_in_the_high_byte() -> None:
    said = read(FC_FORM, e4=element(4, 0xFE16, dialect=FC))  # -2, current
    assert (said.conversion, said.unit) == (-2, "A")
    # The same word read the PROFIdrive way is size index 0xFE and conversion 22: unknown.
    assert read(PROFIDRIVE_FORM, e4=element(4, 0xFE16)).conversion is None


def test_fc_word_limits_by_the_types_sign() -> None:
    low = element(7, 0xFF9C, dialect=FC)
    assert read(FC_FORM, e1=element(1, 3, dialect=FC), e7=low).low_raw == -100  # Int16
    assert read(FC_FORM, e1=element(1, 6, dialect=FC), e7=low).low_raw == 0xFF9C  # UInt16


def test_fc_int16_limit_in_the_fixed_4_word_block() -> None:
    """The guide: "The data type of Lower limit is the same as for the parameter
    itself"; over FC it is in PWE low of the 4-word PKW block."""
    answer = pkw.decode_response(bytes.fromhex("3001 0007 0000 FF9C"), FC, FC.default_ind_layout)
    assert isinstance(answer, pkw.DescriptionResponse)
    said = read_elements(FC_FORM, {1: element(1, 3, dialect=FC), 7: answer})  # Int16
    assert said.low_raw == -100


@pytest.mark.parametrize(
    ("word", "unit"), [(0x0008, "J"), (0x4B08, "J"), (0x0011, "K"), (0x6411, "°C")]
)
def test_fc_unit_index_table(word: int, unit: str) -> None:
    """FC 300 Design Guide, "Read parameter description", the unit index table: energy
    (8) is J at conversion 0 and kWh at 75 (3 600 000 J); temperature (17) is K at 0 and
    degrees C at 100."""
    assert read(FC_FORM, e4=element(4, word, dialect=FC)).unit == unit


def test_fc_element_2_says_whether_it_is_an_array() -> None:
    assert read(FC_FORM, e1=element(1, 6, dialect=FC), e2=element(2, 10, dialect=FC)).array == 10
    assert read(FC_FORM, e1=element(1, 6, dialect=FC), e2=element(2, 0, dialect=FC)).array is None


# ---------------------------- MG.33.C4.02, section 5 "Parameter description": the identifier


def test_profidrive_identifier_bit_14_is_an_array() -> None:
    """Bit 14 "Array", bits 0-7 the data type: 0x4006 is an array of Unsigned16."""
    said = read(PROFIDRIVE_FORM, e1=element(1, 0x4006), e2=element(2, 10))
    assert (said.type_code, said.type_name, said.vtype) == (6, "UInt16", ValueType.U16)
    assert said.array == 10 and said.read_only is False
    # Without bit 14 element 2 does not make it an array.
    assert read(PROFIDRIVE_FORM, e1=element(1, 0x0006), e2=element(2, 10)).array is None


def test_profidrive_identifier_bit_9_is_read_only() -> None:
    said = read(PROFIDRIVE_FORM, e1=element(1, 0x0206))
    assert said.read_only is True and said.type_code == 6


def test_profidrive_identifier_bit_8_leaves_the_variable_attribute_out() -> None:
    """Bit 8: "standardisation factor and variable attribute not relevant"."""
    attribute = element(4, 0x16FE)  # would be current, conversion -2
    said = read(PROFIDRIVE_FORM, e1=element(1, 0x0106), e4=attribute)
    assert (said.conversion, said.unit, said.scaling) == (None, None, None)
    assert read(PROFIDRIVE_FORM, e1=element(1, 0x0006), e4=attribute).conversion == -2


def test_profidrive_a_strings_element_2_is_its_length() -> None:
    """Element 2: "the string length, if the parameter value is a string"."""
    said = read(PROFIDRIVE_FORM, e1=element(1, 9), e2=element(2, 16))
    assert said.vtype is ValueType.TEXT and said.array is None


def test_profidrive_name_of_16_characters() -> None:
    """The name is "limited to 16 characters, e.g. "LANGUAGE" for parameter 1"."""
    name = b"LANGUAGE".ljust(16, b" ")
    ak = pkw.response_id(PROFIDRIVE, Reply.DESCRIPTION)
    answer = pkw.DescriptionResponse(ak, 1, 6, int.from_bytes(name[:4], "big"), name)
    assert read_elements(PROFIDRIVE_FORM, {6: answer}).name == "LANGUAGE"


# --------------------- variable attribute: first byte size index, second conversion index


@pytest.mark.parametrize(
    ("word", "conversion", "unit", "raw", "value"),
    [
        (0x16FE, -2, "A", 1234, 12.34),  # size 22 current, -2
        (0x04FD, -3, "s", 1000, 1.0),  # size 4 time in ms (6.4.3: ms is conversion -3)
        (0x1C00, 0, "Hz", 50, 50.0),  # size 28 frequency
        (0x09FD, -3, "W", 5000, 5.0),  # size 9 power in mW
        (0x1500, 0, "V", 400, 400.0),  # size 21 voltage
    ],
)
def test_profidrive_variable_attribute(
    word: int, conversion: int, unit: str, raw: int, value: float
) -> None:
    said = read(PROFIDRIVE_FORM, e1=element(1, 7), e4=element(4, word), e7=element(7, raw, DWORD))
    assert (said.conversion, said.unit) == (conversion, unit)
    assert said.minimum == pytest.approx(value)


def test_a_size_index_the_table_does_not_give_a_unit_for() -> None:
    """Rotation (11) and unknown indexes: the conversion is known, the unit is not."""
    said = read(PROFIDRIVE_FORM, e4=element(4, 0x0B43))  # 11, conversion 67
    assert said.conversion == 67 and said.unit is None


@pytest.mark.parametrize(
    ("form", "word"),
    [(PROFIDRIVE_FORM, 0x1632), (FC_FORM, 0x3216), (PROFIDRIVE_FORM, 0x1680)],
)
def test_an_unknown_conversion_index_is_none(form: DescriptionForm, word: int) -> None:
    said = read(form, e1=element(1, 6), e4=element(4, word), e7=element(7, 10, DWORD))
    assert (said.conversion, said.unit, said.scaling) == (None, None, None)
    assert said.minimum == 10.0  # unscaled: nothing to scale it by


# ----------------------------- limits: "Format is 32 bit signed" (MG.33.C4.02, section 5)


@pytest.mark.parametrize(
    ("type_code", "raw", "number"),
    [
        (3, 0xFFFFFF9C, -100),  # Int16
        (4, 0xFFFFFF9C, -100),  # Int32
        (6, 0x0000FFFF, 0xFFFF),  # UInt16
        (6, 0xFFFFFF9C, None),  # UInt16 below 0
        (7, 0x7FFFFFFF, 0x7FFFFFFF),  # UInt32
        (7, 0xFFFFFFFF, None),  # -1 as 32 bit signed: no UInt32
        (3, 0x00010000, None),  # outside Int16
    ],
)
def test_profidrive_limits_are_32_bit_signed(type_code: int, raw: int, number: int | None) -> None:
    said = read(PROFIDRIVE_FORM, e1=element(1, type_code), e7=element(7, raw, DWORD))
    assert said.low_raw == number


def test_profidrive_float_limits_are_the_floats_bits() -> None:
    bits = int.from_bytes(struct.pack(">f", 650.0), "big")
    said = read(PROFIDRIVE_FORM, e1=element(1, 8), e8=element(8, bits, DWORD))
    assert said.high_raw == 650.0 and said.maximum == 650.0


def test_no_text_limits() -> None:
    said = read(PROFIDRIVE_FORM, e1=element(1, 9), e7=element(7, 5, DWORD))
    assert said.low_raw is None


# ---------------------------------------------------------------------- which form


@pytest.mark.parametrize(
    ("dialect", "form"),
    [
        (FC, FC_FORM),
        (USS, PROFIDRIVE_FORM),
        (PROFIDRIVE, PROFIDRIVE_FORM),
        (DANFOSS_PCV, PROFIDRIVE_FORM),  # the FC drive's PROFIBUS PCV channel: MG.33.C4.02
        (HITACHI_SJPB, None),  # no AK 4
    ],
)
def test_form_of(dialect: Dialect, form: DescriptionForm | None) -> None:
    assert form_of(dialect) is form


# ------------------ FC 300 Design Guide, "Default value (index 20)" and "Additional
# characteristics (index 21)"; FC 300 PROFIBUS manual MG.33.C2.02, "Identifier ID"


@pytest.mark.parametrize(
    ("bits", "no_bus", "read_only", "not_running", "power_unit"),
    [
        (0, False, False, False, False),
        (1 << 9, True, False, False, False),  # "Bit 9 indicates No bus Access"
        (1 << 10, False, True, False, False),  # 10 Std Bus Read Only
        (1 << 11, False, True, False, False),  # 11 Profibus Read Only
        (1 << 13, False, False, True, False),  # "cannot be changed while running"
        (1 << 15, False, False, False, True),  # PowerUnitDependency
        (0b001, False, False, False, True),  # bits 0-2: "power unit-depending values"
        (0b100, False, False, False, True),
        (0b11 << 7, False, False, False, False),  # bits 7-8: LCP access, not the bus's
    ],
)
def test_fc_additional_characteristics_bits_as_the_guide_lists_them(
    bits: int, no_bus: bool, read_only: bool, not_running: bool, power_unit: bool
) -> None:
    found = Characteristics.of(element(21, bits, dialect=FC))
    assert found.no_bus_access is no_bus
    assert found.bus_read_only is read_only
    assert found.not_while_running is not_running
    assert found.power_unit_dependent is power_unit


def test_fc_characteristics_are_read_from_pwe_low() -> None:
    """ "The Additional characteristics returns an answer in PWE low": a high word is not
    part of it."""
    assert Characteristics.of(element(21, 0xFFFF0000, DWORD, FC)).raw == 0


@pytest.mark.parametrize(
    ("vtype", "raw", "width", "factory"),
    [
        (ValueType.U16, 0x01F4, WORD, 500),  # "the same data type as the parameter itself"
        (ValueType.I16, 0xFF9C, WORD, -100),
        (ValueType.I32, 0xFFFFFF9C, DWORD, -100),
        (ValueType.U32, 0x00030D40, DWORD, 200000),
        (ValueType.U16, 0x7777_01F4, DWORD, 500),  # a word type in the low word
        (ValueType.TEXT, 0x41424344, DWORD, None),
        (None, 5, WORD, None),
    ],
)
def test_fc_default_value_is_a_number_of_the_parameters_type(
    vtype: ValueType | None, raw: int, width: pkw.Width, factory: int | None
) -> None:
    assert factory_raw(element(20, raw, width, FC), vtype) == factory


@pytest.mark.parametrize(
    ("identifier", "changed"),
    [
        (0x0006, False),  # U16, nothing else
        (0x1006, True),  # bit 12: "Parameter has been changed from factory setting"
        (0x5207, True),  # with bit 14 (array) and bit 9 (read-only)
        (0x2006, False),  # bit 13: "can be reset only", another bit
    ],
)
def test_profidrive_identifier_bit_12_tells_a_change_from_the_factory_setting(
    identifier: int, changed: bool
) -> None:
    assert changed_from_factory(element(1, identifier)) is changed
    # The rest of the identifier reads as before: the type and read-only bits.
    assert read(PROFIDRIVE_FORM, e1=element(1, identifier)).type_code == identifier & 0xFF


# ------------------------------------------------------- what a master reads, and nothing


def test_a_master_reads_the_limits_only_of_what_it_may_write() -> None:
    """Elements 1 type, 2 size, 4 scaling, 6 name; 7 and 8 the limits (both forms)."""
    assert elements_to_read(limits=False) == (1, 2, 4, 6)
    assert elements_to_read(limits=True) == (1, 2, 4, 6, 7, 8)


def test_a_description_of_nothing_says_nothing() -> None:
    said = read_elements(PROFIDRIVE_FORM, {})
    assert said.empty and said == DriveDescription()
    assert (said.vtype, said.type_name, said.scaling) == (None, "", None)
    assert (said.minimum, said.maximum) == (None, None)
    assert not read(PROFIDRIVE_FORM, e1=element(1, 6)).empty


def test_a_float_limit_in_one_word_cannot_be_read() -> None:
    """A FloatingPoint32 limit is four bytes: a one-word answer does not hold it."""
    said = read(FC_FORM, e1=element(1, 8, dialect=FC), e7=element(7, 0x4248, WORD, FC))
    assert said.vtype is ValueType.F32 and said.low_raw is None
