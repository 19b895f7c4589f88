"""Parameter notation, value types, conversion-index scaling."""

from __future__ import annotations

import math
import struct
from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.params import (
    ParameterNotationError,
    ParameterRef,
    Rounding,
    Scaling,
    ValueType,
    check_limits,
    decode_text,
    decode_value,
    encode_text,
    encode_value,
    parse_parameter,
    parse_type,
)
from pkwbus.protocol.pkw import Width


@pytest.mark.parametrize(
    ("text", "pnu", "index", "name"),
    [
        ("16-13", 1613, None, "16-13"),
        ("3-41", 341, None, "3-41"),
        ("03-41", 341, None, "3-41"),
        ("1613", 1613, None, "1613"),
        ("r0021", 21, None, "r0021"),
        ("p1082", 1082, None, "p1082"),
        ("P7841[2]", 7841, 2, "P7841"),
        ("15-30[9]", 1530, 9, "15-30"),
        (" 0-01 ", 1, None, "0-01"),
    ],
)
def test_notation(text: str, pnu: int, index: int | None, name: str) -> None:
    ref = parse_parameter(text)
    assert ref == ParameterRef(pnu, index, name)


def test_str_carries_the_index() -> None:
    assert str(parse_parameter("P7841[2]")) == "P7841[2]"
    assert str(parse_parameter("16-13")) == "16-13"


@pytest.mark.parametrize(
    "text", ["", "16-1", "16-133", "x21", "r", "16-13[", "16-13[-1]", "1e3", "p-5", "16 13", "[2]"]
)
def test_bad_notation(text: str) -> None:
    with pytest.raises(ParameterNotationError, match="not a parameter"):
        parse_parameter(text)


def test_numbers_too_large() -> None:
    with pytest.raises(ParameterNotationError, match="above 65535"):
        parse_parameter("70000")
    with pytest.raises(ParameterNotationError, match="index 256"):
        parse_parameter("r0947[256]")


@given(st.text(max_size=20))
def test_notation_fuzz_raises_only_notation_errors(text: str) -> None:
    try:
        ref = parse_parameter(text)
    except ParameterNotationError:
        return
    assert 0 <= ref.pnu <= 0xFFFF


def test_types() -> None:
    assert parse_type("F32") is ValueType.F32
    assert ValueType.U16.width is Width.WORD
    assert ValueType.I32.width is Width.DWORD
    assert ValueType.TEXT.width is None
    with pytest.raises(LocalProtocolError, match="unknown type"):
        parse_type("u8")


@pytest.mark.parametrize(
    ("index", "factor"),
    [
        (-2, Fraction(1, 100)),
        (0, 1),
        (3, 1000),
        (67, Fraction(1, 60)),
        (74, 3600),
        (75, 3_600_000),
        (100, 1),
        (-7, Fraction(1, 10**7)),
        (6, 10**6),
    ],
)
def test_conversion_indexes(index: int, factor: Fraction) -> None:
    assert Scaling.conversion(index).factor == factor


def test_unknown_conversion_index() -> None:
    with pytest.raises(LocalProtocolError, match="conversion index 7"):
        Scaling.conversion(7)


def test_scaling_examples_from_the_manuals() -> None:
    assert decode_value(1000, Width.DWORD, ValueType.U32, Scaling.conversion(-2)) == 10.0
    assert decode_value(524, Width.WORD, ValueType.U16, Scaling.conversion(-2)) == 5.24
    assert encode_value(10.0, ValueType.U32, Scaling.conversion(-2)) == 1000
    assert encode_value("5.24", ValueType.U16, Scaling.conversion(-2)) == 524


def test_unscaled_and_untyped_values() -> None:
    assert decode_value(0xFFFF, Width.WORD, None) == 0xFFFF
    assert decode_value(0xFFFF, Width.WORD, ValueType.I16) == -1
    assert decode_value(0xFFFFFFFE, Width.DWORD, ValueType.I32) == -2
    # A signed 32-bit parameter answered with a word is sign-extended from 16 bits.
    assert decode_value(0xFFFF, Width.WORD, ValueType.I32) == -1
    assert decode_value(7, Width.WORD, ValueType.U16, Scaling.scale(2.0)) == 14


def test_f32() -> None:
    assert decode_value(0x42480000, Width.DWORD, ValueType.F32) == 50.0
    assert encode_value(50.0, ValueType.F32) == 0x42480000
    with pytest.raises(RemoteProtocolError, match="f32"):
        decode_value(0x4248, Width.WORD, ValueType.F32)
    with pytest.raises(LocalProtocolError, match="f32 range"):
        encode_value(1e300, ValueType.F32)
    scaled = decode_value(0x42480000, Width.DWORD, ValueType.F32, Scaling.scale(0.5))
    assert scaled == 25.0


def test_text_is_not_a_number() -> None:
    with pytest.raises(LocalProtocolError):
        encode_value(1, ValueType.TEXT)
    with pytest.raises(RemoteProtocolError):
        decode_value(1, Width.WORD, ValueType.TEXT)
    assert decode_text(b"FC-302\x00\x00  ") == "FC-302"
    assert encode_text("Pump 1") == b"Pump 1"
    with pytest.raises(LocalProtocolError):
        encode_text("Pumpe \u263a")


def test_rounding_is_explicit() -> None:
    ramp = Scaling.conversion(-2)
    assert encode_value(10.005, ValueType.U32, ramp) == 1001  # half away from zero
    assert encode_value(-10.005, ValueType.I32, ramp) == (-1001) & 0xFFFFFFFF
    with pytest.raises(LocalProtocolError, match=r"resolution 0\.01"):
        encode_value(10.004, ValueType.U32, ramp, Rounding.EXACT)
    assert encode_value(10.01, ValueType.U32, ramp, Rounding.EXACT) == 1001


def test_type_ranges() -> None:
    with pytest.raises(LocalProtocolError, match="u16 range"):
        encode_value(65536, ValueType.U16)
    with pytest.raises(LocalProtocolError, match="i16 range"):
        encode_value(-32769, ValueType.I16)
    with pytest.raises(LocalProtocolError, match="u32 range"):
        encode_value(-1, ValueType.U32)
    assert encode_value(-1, ValueType.I16) == 0xFFFF
    with pytest.raises(LocalProtocolError, match="not a number"):
        encode_value("ten", ValueType.U16)
    with pytest.raises(LocalProtocolError, match="finite"):
        encode_value("nan", ValueType.U16)


def test_limits() -> None:
    check_limits(5, 0, 10)
    with pytest.raises(LocalProtocolError, match="below the minimum 1 s"):
        check_limits(0.5, 1, 3600, "s")
    with pytest.raises(LocalProtocolError, match="above the maximum 3600"):
        check_limits(3600.01, 1, 3600)


def test_bad_scale() -> None:
    with pytest.raises(LocalProtocolError):
        Scaling.scale(0)
    with pytest.raises(LocalProtocolError):
        Scaling.scale(math.inf)


int_types = st.sampled_from([ValueType.U16, ValueType.I16, ValueType.U32, ValueType.I32])
conversions = st.sampled_from([-7, -3, -2, -1, 0, 1, 2, 6, 67, 74, 75, 100])


@given(vtype=int_types, conv=conversions, data=st.data())
def test_integer_round_trip(vtype: ValueType, conv: int, data: st.DataObject) -> None:
    low, high = vtype.bounds
    raw_number = data.draw(st.integers(low, high))
    scaling = Scaling.conversion(conv)
    width = vtype.width
    assert width is not None
    raw = raw_number & (0xFFFF if width is Width.WORD else 0xFFFFFFFF)
    value = decode_value(raw, width, vtype, scaling)
    exact = Fraction(raw_number) * scaling.factor
    assert Fraction(value) == exact or math.isclose(value, float(exact), rel_tol=1e-12)
    if Fraction(value) == exact:
        assert encode_value(value, vtype, scaling) == raw


@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_f32_round_trip(number: float) -> None:
    raw = encode_value(number, ValueType.F32)
    assert raw == int.from_bytes(struct.pack(">f", number), "big")
    assert decode_value(raw, Width.DWORD, ValueType.F32) == number
