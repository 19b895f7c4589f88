"""Parameter notation, value types, conversion-index scaling."""

from __future__ import annotations

import math
import struct
from decimal import Decimal
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw import Width
from pkwbus.protocol.values import (
    UNSCALED,
    ParameterNotationError,
    ParameterRef,
    Rounding,
    Scaling,
    ValueType,
    canonical,
    check_limits,
    decode_text,
    decode_value,
    encode_exact,
    encode_text,
    encode_value,
    parse_parameter,
    parse_type,
)


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
    with pytest.raises(LocalProtocolError, match=r"not a multiple of 0\.01: nearest 10 or 10\.01"):
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


# ------------------------------------------------------ one name per drive


@pytest.mark.parametrize("text", ["3-41", "03-41", "341", "0341", "00341"])
def test_a_danfoss_drive_has_one_name_per_parameter(text: str) -> None:
    assert canonical(parse_parameter(text), danfoss=True) == ParameterRef(341, None, "3-41")
    assert str(canonical(parse_parameter(text + "[2]"), danfoss=True)) == "3-41[2]"


@pytest.mark.parametrize("text", ["p0341", "P341", "r0341[2]"])
def test_siemens_notation_on_a_danfoss_drive_names_the_fc_form(text: str) -> None:
    ref = parse_parameter(text)
    with pytest.raises(ParameterNotationError, match=r"Siemens.*write 3-41"):
        canonical(ref, danfoss=True)


@pytest.mark.parametrize(
    ("text", "prefix", "name"),
    [
        ("r21", "r", "r0021"),
        ("P1082", "p", "p1082"),
        ("1082", "p", "p1082"),
        ("p0021", "r", "r0021"),  # the drive's catalog or configuration decides
        ("p2000", "", "2000"),  # neither knows it: the plain number
        ("20-00", "", "2000"),
    ],
)
def test_other_drives_name_it_with_the_known_prefix(text: str, prefix: str, name: str) -> None:
    assert canonical(parse_parameter(text), danfoss=False, prefix=prefix).name == name


# ------------------------------------------------------------ exact values


def _refusal(*args: object, **kwargs: object) -> str:
    with pytest.raises(LocalProtocolError) as caught:
        encode_exact(*args, **kwargs)  # type: ignore[arg-type]
    return str(caught.value)


def test_a_value_off_the_step_names_the_nearest_steps() -> None:
    ramp = Scaling.conversion(-2)
    message = _refusal("12.345", ValueType.U32, ramp, parameter="3-41")
    assert message == "12.345 is not a multiple of 0.01 for 3-41: nearest 12.34 or 12.35"
    assert encode_exact("12.34", ValueType.U32, ramp) == 1234
    assert encode_exact(12.34, ValueType.U32, ramp) == 1234
    # a neighbour outside the type or the limits is not offered
    assert _refusal("655.355", ValueType.U16, ramp).endswith("nearest 655.35")
    assert _refusal("1.005", ValueType.U16, ramp, maximum=1.005).endswith("nearest 1")


@pytest.mark.parametrize("value", [1e-50, "1e-50", -1e-50, 1e-45, "1.234e-44", 1e-40])
def test_f32_refuses_underflow_and_subnormals(value: float | str) -> None:
    message = _refusal(value, ValueType.F32, parameter="p1120")
    assert "below the smallest f32" in message and "for p1120" in message
    assert message.endswith(("nearest 0 or 1.1754944e-38", "nearest 0 or -1.1754944e-38"))


@pytest.mark.parametrize(
    ("value", "nearest"),
    [
        ("0.30000001", "nearest 0.29999998 or 0.3"),
        ("16777217", "nearest 16777216 or 16777218"),
        ("0.10000000149", "nearest 0.099999994 or 0.1"),
    ],
)
def test_f32_refuses_what_it_cannot_hold(value: str, nearest: str) -> None:
    assert _refusal(value, ValueType.F32).endswith(nearest)


@pytest.mark.parametrize(
    "value", [0.1, "0.1", 50.0, "25.5", "1.2e-38", "3.4028235e38", 0, 0.10000000149011612]
)
def test_f32_takes_what_it_holds(value: float | str) -> None:
    raw = encode_exact(value, ValueType.F32)
    assert raw == int.from_bytes(struct.pack(">f", float(value)), "big")


@settings(deadline=None)
@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_a_single_as_pkwbus_reads_it_can_be_written_back(number: float) -> None:
    bits = int.from_bytes(struct.pack(">f", number), "big")
    if number != 0 and abs(number) < 2.0**-126:
        with pytest.raises(LocalProtocolError, match="below the smallest f32"):
            encode_exact(repr(number), ValueType.F32)
        return
    assert encode_exact(repr(number), ValueType.F32) == (bits if number else 0)
    assert encode_exact(number, ValueType.F32) == (bits if number else 0)


def _single(text: str) -> int:
    return int.from_bytes(struct.pack(">f", float(text)), "big")


@settings(deadline=None)
@given(
    st.decimals(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6, places=4),
    st.sampled_from([ValueType.F32, ValueType.I32]),
    st.sampled_from([-3, -2, -1, 0, 1, 67]),
)
def test_a_refusal_names_values_that_are_taken(
    number: Decimal, vtype: ValueType, conversion: int
) -> None:
    scaling = Scaling.conversion(conversion) if vtype is not ValueType.F32 else UNSCALED
    text = str(number)
    try:
        raw = encode_exact(text, vtype, scaling)
    except LocalProtocolError as exc:
        named = str(exc).partition("nearest ")[2].split(" or ")
        assert len(named) == 2, exc
        for near in named:
            if not near.startswith("~"):  # 1/60 steps have no exact decimal to offer
                encode_exact(near, vtype, scaling)
        if vtype is ValueType.F32:  # the two singles either side of the number
            low, high = sorted(
                Fraction(struct.unpack(">f", struct.pack(">f", float(n)))[0]) for n in named
            )
            assert low < Fraction(number) < high
        else:  # the two steps either side
            for n in named:
                if not n.startswith("~"):
                    assert abs(Fraction(n) - Fraction(number)) < scaling.factor
        return
    if vtype is ValueType.F32:  # the single nearest the number
        assert raw == _single(text)
    else:
        signed = raw - (1 << 32) if raw >> 31 else raw
        assert signed * scaling.factor == Fraction(number)


# ------------------------------------------------------------- what is no value


def test_a_text_too_long_to_be_a_number_is_refused_unread() -> None:
    with pytest.raises(
        LocalProtocolError, match=r"^1{20}\.\.\. is not a parameter value \(too long\)"
    ):
        encode_exact("1" * 101, ValueType.U32)


@pytest.mark.parametrize("number", [math.inf, -math.inf, math.nan])
def test_an_infinite_float_is_no_f32_value(number: float) -> None:
    with pytest.raises(LocalProtocolError, match="is not a finite number"):
        encode_value(number, ValueType.F32)


def test_a_value_whose_neighbouring_steps_are_all_outside_the_limits() -> None:
    message = _refusal("0.5", ValueType.U16, minimum=0.2, maximum=0.8)
    assert message == "0.5 is not a multiple of 1: no value near it is within the limits"


@pytest.mark.parametrize("value", ["1e39", "-3.5e38"])
def test_a_value_beyond_the_largest_f32_is_refused(value: str) -> None:
    # the largest single is 3.4028235e38 (taken, see test_f32_takes_what_it_holds)
    assert _refusal(value, ValueType.F32) == f"{value} is outside the f32 range"


def test_no_subnormal_is_offered_as_the_nearest_f32() -> None:
    # Just below the smallest normal single (1.1754944e-38): its lower neighbour is a
    # subnormal, no exact value, so only the normal one above is named.
    message = _refusal("1.17549435e-38", ValueType.F32)
    assert message == "1.17549435e-38 has no exact f32 value: nearest 1.1754944e-38"


@pytest.mark.parametrize(
    ("value", "nearest"),
    [
        # 1 + 2^-24 (the midpoint of the singles 1 and 1.0000001) + 1e-28: a double
        # rounds it onto the midpoint; it is nearer 1.0000001 and exactly neither.
        ("1.0000000596046447753906250001", "nearest 1 or 1.0000001"),
        ("0.9999999701976776123046875001", "nearest 0.99999994 or 1"),
    ],
)
def test_a_value_a_double_puts_between_two_singles(value: str, nearest: str) -> None:
    assert _refusal(value, ValueType.F32) == f"{value} has no exact f32 value: {nearest}"


def test_the_whole_number_types_are_the_ones_with_bounds() -> None:
    assert [t for t in ValueType if t.whole] == [
        ValueType.U16, ValueType.I16, ValueType.U32, ValueType.I32,
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("value", "vtype", "message"),
    [
        ("-1.5", ValueType.U16, "-1.5 is raw -2, outside the u16 range 0..65535"),
        ("32768.5", ValueType.I16, "32768.5 is raw 32769, outside the i16 range -32768..32767"),
    ],
)
def test_a_value_off_the_step_and_outside_the_type_says_the_range(
    value: str, vtype: ValueType, message: str
) -> None:
    assert _refusal(value, vtype) == message
