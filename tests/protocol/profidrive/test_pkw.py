"""PKW requests carried as PROFIdrive parameter requests (data record 47), on the
vendors' byte examples: pkwbus.protocol.profidrive.pkw."""

from __future__ import annotations

import struct

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.fields import Store, Width
from pkwbus.protocol.profibus.dp.ppo import dp_dialect
from pkwbus.protocol.profidrive.parameters import (
    MAX_PARAMETERS,
    MAX_RECORD,
    Attribute,
    Format,
    ParameterAddress,
    RequestId,
    Values,
)
from pkwbus.protocol.profidrive.pkw import RecordItem, carried, fits, record_request
from pkwbus.protocol.values.types import ValueType

SIEMENS = dp_dialect("profidrive")
DANFOSS = dp_dialect("danfoss-pcv")

# SINAMICS G120X operating instructions, "Parameter channel", example: change p1121
# (ramp-down time, FloatingPoint) to 12.15 s in RAM; reference 0x80, DO 1.
G120X_CHANGE_P1121 = bytes.fromhex("80 02 01 01 10 01 04 61 00 00 08 01 41 42 66 66")
# SINAMICS field description of the parameter request (Industrial Security
# Configuration Manual A5E36912609A, table A-23): read r0002 from DO 1.
SINAMICS_READ_R0002 = bytes.fromhex("80 01 01 01 10 01 00 02 00 00")


def _float_bits(value: float) -> int:
    return int.from_bytes(struct.pack(">f", value), "big")


def test_the_sinamics_read_of_r0002_byte_for_byte() -> None:
    request = record_request(
        [RecordItem(pkw.read(SIEMENS, 2))], reference=0x80, axis=1, dialect="profidrive"
    )
    assert request.encode() == SINAMICS_READ_R0002


def test_the_g120x_change_of_p1121_byte_for_byte() -> None:
    # A PKW double word change in RAM of a FloatingPoint parameter: its value travels
    # as a float, not as the double word's bits.
    change = pkw.write(SIEMENS, 1121, _float_bits(12.15), Width.DWORD)
    item = RecordItem(change, ValueType.F32)
    request = record_request([item], reference=0x80, axis=1, dialect="profidrive")
    assert request.encode() == G120X_CHANGE_P1121


def test_reads_go_together_with_their_array_elements() -> None:
    items = [
        RecordItem(pkw.read(SIEMENS, 21)),
        RecordItem(pkw.read(SIEMENS, 945, 3)),  # r0945[3]
    ]
    request = record_request(items, reference=5, axis=1, dialect="profidrive")
    assert request.request_id is RequestId.READ
    assert request.addresses == (ParameterAddress(21), ParameterAddress(945, 3))
    assert request.changes == ()


def test_a_description_element_is_attribute_0x20_with_the_element_as_subindex() -> None:
    # Danfoss axis 0 (MCA 101 programming manual, 5.2.13); description element 2.
    item = RecordItem(pkw.read_description(DANFOSS, 302, 2))
    request = record_request([item], reference=1, axis=0, dialect="danfoss-pcv")
    assert request.addresses == (ParameterAddress(302, 2, 1, Attribute.DESCRIPTION),)
    data = request.encode()
    assert data[4:10] == bytes((0x20, 1)) + (302).to_bytes(2, "big") + (2).to_bytes(2, "big")


@pytest.mark.parametrize(
    ("vtype", "raw", "width", "values"),
    [
        (ValueType.U16, 0xFFFF, Width.WORD, Values(Format.U16, (0xFFFF,))),
        (ValueType.I16, 0xFFFF, Width.WORD, Values(Format.I16, (-1,))),
        (ValueType.I16, 0x7FFF, Width.WORD, Values(Format.I16, (0x7FFF,))),
        (ValueType.I32, 0x80000000, Width.DWORD, Values(Format.I32, (-(1 << 31),))),
        (ValueType.U32, 0x80000000, Width.DWORD, Values(Format.U32, (1 << 31,))),
        (ValueType.F32, _float_bits(-0.5), Width.DWORD, Values(Format.FLOAT, (-0.5,))),
        # type not known: "Bytes, words and double words are also possible as a
        # substitute" (SINAMICS field description of the parameter request)
        (None, 0x1234, Width.WORD, Values(Format.WORD, (0x1234,))),
        (None, 0x12345678, Width.DWORD, Values(Format.DOUBLE_WORD, (0x12345678,))),
    ],
)
def test_a_change_carries_its_value_in_the_parameters_own_format(
    vtype: ValueType | None, raw: int, width: Width, values: Values
) -> None:
    item = RecordItem(pkw.write(SIEMENS, 1082, raw, width), vtype)
    request = record_request([item], reference=1, axis=1, dialect="profidrive")
    assert request.request_id is RequestId.CHANGE
    assert request.addresses == (ParameterAddress(1082),)
    assert request.changes == (values,)
    data = request.encode()
    assert data[10:] == values.encode()  # the value block after head and address
    # the two's complement bits of the PKW value are the bits on the wire
    assert int.from_bytes(data[12:], "big") == raw


def test_an_array_element_change_addresses_its_subindex() -> None:
    item = RecordItem(pkw.write(SIEMENS, 1001, 300, Width.WORD, index=2), ValueType.U16)
    request = record_request([item], reference=1, axis=1, dialect="profidrive")
    assert request.addresses == (ParameterAddress(1001, 2),)


def test_a_change_to_ram_and_eeprom_is_refused_saying_ram_only() -> None:
    item = RecordItem(pkw.write(SIEMENS, 1121, 0, Width.DWORD, store=Store.EEPROM))
    with pytest.raises(LocalProtocolError, match="goes to RAM only"):
        record_request([item], reference=1, axis=1, dialect="profidrive")


def test_what_a_parameter_request_cannot_carry_is_refused() -> None:
    read = RecordItem(pkw.read(SIEMENS, 2))
    change = RecordItem(pkw.write(SIEMENS, 1121, 0, Width.DWORD))
    with pytest.raises(LocalProtocolError, match="of no parameters"):
        record_request([], reference=1, axis=1, dialect="profidrive")
    with pytest.raises(LocalProtocolError, match="a change goes alone"):
        record_request([read, change], reference=1, axis=1, dialect="profidrive")
    text_write = RecordItem(pkw.write_text(SIEMENS, 2, b"pump"))
    with pytest.raises(LocalProtocolError, match="texts do not travel in data record 47"):
        record_request([text_write], reference=1, axis=1, dialect="profidrive")
    text_read = RecordItem(pkw.read_text(SIEMENS, 2))
    with pytest.raises(LocalProtocolError, match="read/write text request does not travel"):
        record_request([read, text_read], reference=1, axis=1, dialect="profidrive")
    count = RecordItem(pkw.request(SIEMENS, pkw.Command.READ_ARRAY_COUNT, 945))
    with pytest.raises(LocalProtocolError, match="number of array elements request does not"):
        record_request([count], reference=1, axis=1, dialect="profidrive")


def test_carried_says_why_a_request_stays_out_of_data_record_47() -> None:
    assert carried(pkw.read(SIEMENS, 2)) == ""
    assert carried(pkw.write(SIEMENS, 1121, 0, Width.DWORD)) == ""
    assert carried(pkw.read_description(SIEMENS, 1121, 1)) == ""
    text = "a read/write text request does not travel in data record 47"
    assert carried(pkw.read_text(SIEMENS, 2)) == text
    assert carried(pkw.write_text(SIEMENS, 2, b"pump")) == text
    count = pkw.request(SIEMENS, pkw.Command.READ_ARRAY_COUNT, 945)
    assert carried(count) == (
        "a read number of array elements request does not travel in data record 47"
    )


def test_thirty_nine_value_reads_fit_one_record_and_forty_do_not() -> None:
    # A request of n reads is 4 + 6n bytes; its response at most 4 + 6n too
    # (format, count and a double word each): 39 x 6 + 4 = 238 <= 240.
    assert MAX_PARAMETERS == 39 and MAX_RECORD == 240
    assert fits(1) and fits(MAX_PARAMETERS)
    assert not fits(MAX_PARAMETERS + 1)


def test_a_slave_that_takes_less_than_240_bytes_takes_fewer_reads() -> None:
    # C1_Max_Data_Len = 100: 4 + 6 x 16 = 100 bytes fit, 17 reads (106 bytes) do not.
    assert fits(16, max_data=100)
    assert not fits(17, max_data=100)
    # a slave that says it takes more than 240 still gets no more than a record holds
    assert not fits(MAX_PARAMETERS + 1, max_data=1000)
    assert fits(MAX_PARAMETERS, max_data=1000)
