"""The fuzzers' properties as Hypothesis tests, small enough for every CI run.

The atheris harnesses in fuzz/ check the same properties for minutes at a
time (docs/fuzzing.md). Bugs they found are pinned at the end of this module
with the minimal input (F-PKW-*, F-PAR-*, F-CAT-*), each asserting the fixed
behaviour.
"""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pkwbus.catalog import CatalogError
from pkwbus.catalog.loader import _parse_catalog
from pkwbus.master.carriers import SerialCarrier, carrier_for
from pkwbus.master.planning.answers import ErrorKind, Failure, Reply
from pkwbus.master.planning.carrier import Item
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol import values as params
from pkwbus.protocol.errors import LocalProtocolError, ProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import DIALECTS, USS, Command, Dialect, IndLayout
from pkwbus.protocol.serial.telegram import (
    MAX_TELEGRAM,
    USS_DEFAULT,
    BlockShape,
    Deframer,
    DeframerEvent,
    FramingError,
    Skipped,
    Telegram,
    fc_lengths,
    frame,
    uss_lengths,
)

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

LENGTH_SETS = {
    "fc": fc_lengths(),
    "uss-any": uss_lengths(),
    "uss-4-2": uss_lengths([USS_DEFAULT]),
    "uss-3-2": uss_lengths([BlockShape(3, 2)]),
}
DIALECT_LAYOUTS = [(d, layout) for d in DIALECTS.values() for layout in IndLayout]

# ------------------------------------------------------------------ deframer


def check_events(events: list[DeframerEvent]) -> None:
    assert all(isinstance(e, Telegram | FramingError) for e in events), events


def feed_chunks(deframer: Deframer, chunks: list[bytes]) -> list[DeframerEvent]:
    out: list[DeframerEvent] = []
    for chunk in chunks:
        out += deframer.feed(chunk)
        assert deframer.buffered <= MAX_TELEGRAM
    return out + deframer.flush()


def cut(data: bytes, sizes: list[int]) -> list[bytes]:
    chunks, pos = [], 0
    for size in sizes:
        if pos >= len(data):
            break
        chunks.append(data[pos : pos + size])
        pos += size
    return [*chunks, data[pos:]] if pos < len(data) else chunks


def summary(events: list[DeframerEvent]) -> tuple[list[DeframerEvent], int]:
    """Events without the skip counts, and the bytes skipped in all: chunking may split a skip."""
    kept = [e for e in events if not isinstance(e, Skipped)]
    return kept, sum(e.count for e in events if isinstance(e, Skipped))


@st.composite
def valid_telegrams(draw: st.DrawFn, lengths: frozenset[int]) -> tuple[Telegram, bytes]:
    lge = draw(st.sampled_from(sorted(lengths)))
    body = draw(st.binary(min_size=lge - 2, max_size=lge - 2))
    adr = draw(st.integers(0, 255))
    return Telegram(adr, body), frame(adr, body)


@st.composite
def line_streams(draw: st.DrawFn) -> tuple[frozenset[int], bytes]:
    """Telegrams, garbage, STX-heavy noise and cut-off telegrams, mixed."""
    lengths = LENGTH_SETS[draw(st.sampled_from(sorted(LENGTH_SETS)))]
    noise = st.binary(max_size=40) | st.lists(
        st.sampled_from(b"\x02\x0e\x06\x00"), max_size=20
    ).map(bytes)
    telegram = valid_telegrams(lengths).map(lambda t: t[1])
    cut_off = telegram.flatmap(lambda w: st.integers(1, len(w) - 1).map(lambda n: w[:n]))
    parts = draw(st.lists(telegram | noise | cut_off, max_size=8))
    return lengths, b"".join(parts)


@FAST
@given(line_streams(), st.lists(st.integers(1, 40), max_size=60))
def test_deframer_whole_byte_by_byte_and_chunks_agree(
    stream: tuple[frozenset[int], bytes], sizes: list[int]
) -> None:
    lengths, data = stream
    whole = feed_chunks(Deframer(lengths), [data])
    one_by_one = feed_chunks(Deframer(lengths), [data[i : i + 1] for i in range(len(data))])
    chunked = feed_chunks(Deframer(lengths), cut(data, sizes))
    for events in (whole, one_by_one, chunked):
        check_events(events)
    assert summary(one_by_one) == summary(whole)
    assert summary(chunked) == summary(whole)


@FAST
@given(st.sampled_from(sorted(LENGTH_SETS)), st.data())
def test_deframer_recovers_a_telegram_after_garbage_and_a_gap(
    name: str, data: st.DataObject
) -> None:
    lengths = LENGTH_SETS[name]
    garbage = data.draw(
        st.binary(max_size=600) | st.binary(max_size=300).map(lambda b: b"\x02" + b)
    )
    telegram, wire = data.draw(valid_telegrams(lengths))
    sizes = data.draw(st.lists(st.integers(1, 64), max_size=20))
    deframer = Deframer(lengths)
    check_events(feed_chunks(deframer, cut(garbage, sizes)))
    assert deframer.buffered == 0
    assert feed_chunks(deframer, cut(wire, sizes)) == [telegram]


# ----------------------------------------------------------------------- PKW


@FAST
@given(st.sampled_from(DIALECT_LAYOUTS), st.binary(max_size=24))
def test_decode_response_only_raises_remote_protocol_error(
    dl: tuple[Dialect, IndLayout], data: bytes
) -> None:
    d, layout = dl
    try:
        resp = pkw.decode_response(data, d, layout)
    except RemoteProtocolError:
        return
    assert isinstance(resp, pkw.PkwResponse)


def read_bits(d: Dialect, layout: IndLayout, head: bytes) -> tuple[int, int, int]:
    """PKE bits, subindex and page byte as the decoder reads them (page -1: no page index)."""
    pke, ind = int.from_bytes(head[:2], "big"), int.from_bytes(head[2:4], "big")
    subindex, other = (ind & 0xFF, ind >> 8) if layout is IndLayout.USS else (ind >> 8, ind & 0xFF)
    pke_bits = pke if d.pnu_bits == 12 else pke & 0xF7FF  # bit 11 of an 11-bit PKE: not read
    return pke_bits, subindex, other & 0xFC if d.page_index else -1


@FAST
@given(st.sampled_from(DIALECT_LAYOUTS), st.binary(min_size=6, max_size=24))
def test_decoded_response_encodes_back_to_the_same_pke_and_ind(
    dl: tuple[Dialect, IndLayout], data: bytes
) -> None:
    d, layout = dl
    if d.page_index:  # F-PKW-1 and F-PKW-2: non-canonical and too large PNUs, pinned below
        assume(data[1] | (data[0] & 0x07) << 8 < pkw.PAGE_SIZE)
        try:
            assume(pkw.decode_response(data, d, layout).pnu <= d.max_pnu)
        except RemoteProtocolError:
            return
    try:
        resp = pkw.decode_response(data, d, layout)
    except RemoteProtocolError:
        return
    words = None if isinstance(resp, pkw.TextResponse) else 3 if len(data) < 8 else 4
    again = pkw.encode_response(resp, d, layout, words)
    assert read_bits(d, layout, again) == read_bits(d, layout, data)
    assert pkw.decode_response(again, d, layout).pnu == resp.pnu


@st.composite
def transactions(draw: st.DrawFn) -> tuple[PkwTransaction, DriveTarget]:
    protocol = draw(st.sampled_from(["fc", "uss"]))
    names = ["fc"] if protocol == "fc" else [n for n in DIALECTS if n != "fc"]
    try:
        target = DriveTarget.create(
            protocol,
            draw(st.integers(1, 30)),
            dialect_name=draw(st.sampled_from(names)),
            ind_layout=draw(st.sampled_from(list(IndLayout))),
            pkw_words=draw(st.sampled_from([None, 3, 4])),
            pzd_words=draw(st.integers(0, 4)),
        )
        command = draw(st.sampled_from(list(Command)))
        text = draw(st.binary(min_size=1, max_size=3)) if command is Command.TEXT else b""
        req = pkw.request(
            target.dialect,
            command,
            draw(st.integers(0, 4095)),
            subindex=draw(st.integers(0, 255)),
            value=draw(st.integers(0, 0xFFFF)),
            text=text if draw(st.booleans()) else b"",
        )
        tx = carrier_for(target).transaction(
            [Item(req)], retries=draw(st.integers(0, 4)), deadline=draw(st.integers(1, 50))
        )
        assert isinstance(tx, PkwTransaction)
        return tx, target
    except LocalProtocolError:
        assume(False)
        raise


def replies(job: PkwTransaction, target: DriveTarget) -> st.SearchStrategy[Reply | Failure]:
    def answer(ak: int, own_pnu: bool, raw: int) -> Reply:
        resp = pkw.ValueResponse(
            ak, job.request.pnu if own_pnu else 7, job.request.subindex, raw, pkw.Width.WORD
        )
        try:
            body = pkw.encode_response(resp, target.dialect, target.ind_layout, 4)
        except LocalProtocolError:
            body = b""
        return Reply(SerialCarrier(target).address, body + bytes(2 * target.shape.pzd_words), 0.01)

    return st.one_of(
        st.binary(max_size=30).map(lambda b: Reply(SerialCarrier(target).address, b, 0.01)),
        st.builds(answer, st.integers(0, 15), st.booleans(), st.integers(0, 0xFFFF)),
        st.builds(Failure, st.sampled_from(list(ErrorKind)), st.just("test")),
    )


@FAST
@given(st.data())
def test_transaction_never_raises_and_ends_by_its_last_retry(data: st.DataObject) -> None:
    job, target = data.draw(transactions())
    counted = 0
    for step in range(int(job.deadline) + 1):  # one step a second, up to the deadline itself
        result = data.draw(replies(job, target))
        if isinstance(result, Failure):
            counted += result.kind not in (ErrorKind.UNEXPECTED, ErrorKind.PORT)
        outcome = job.feed(result, now=float(step))
        if isinstance(result, Failure) and result.kind is ErrorKind.PORT:
            assert outcome is not None
        if outcome is not None:
            assert job.outcome is outcome
            return
        assert counted <= job.retries
        assert step < job.deadline
    raise AssertionError("a job outlived its deadline")


# ------------------------------------------------------------------ notation


@FAST
@given(st.text(max_size=20) | st.from_regex(r"\s*[rRpP]?\d{1,6}(-\d{1,3})?(\[\d{1,4}\])?\s*"))
def test_parse_parameter_only_raises_notation_errors(text: str) -> None:
    try:
        ref = params.parse_parameter(text)
    except params.ParameterNotationError:
        return
    assert 0 <= ref.pnu <= params.MAX_PNU
    assert ref.index is None or 0 <= ref.index <= params.MAX_INDEX


@FAST
@given(st.text(max_size=8) | st.sampled_from([t.value.upper() for t in params.ValueType]))
def test_parse_type_only_raises_local_protocol_error(text: str) -> None:
    with contextlib.suppress(LocalProtocolError):
        params.parse_type(text)


values = st.one_of(
    st.integers(),
    st.floats(),
    st.text(max_size=12),
    st.builds(
        "{}e{}".format, st.decimals(allow_nan=False, allow_infinity=False), st.integers(-5000, 5000)
    ),
)
scalings = st.one_of(
    st.just(params.UNSCALED),
    st.sampled_from(sorted(params.CONVERSION_FACTORS)).map(params.Scaling.conversion),
    st.floats(allow_nan=False, allow_infinity=False).filter(bool).map(params.Scaling.scale),
)


@FAST
@given(
    values,
    st.sampled_from(list(params.ValueType)),
    scalings,
    st.sampled_from(list(params.Rounding)),
)
def test_encode_value_only_raises_protocol_errors(
    value: float | int | str,
    vtype: params.ValueType,
    scaling: params.Scaling,
    rounding: params.Rounding,
) -> None:
    try:
        raw = params.encode_value(value, vtype, scaling, rounding)
    except ProtocolError:
        return
    assert vtype.width is not None
    assert 0 <= raw < 1 << vtype.width.value


@FAST
@given(
    st.sampled_from(list(pkw.Width)).flatmap(
        lambda w: st.tuples(st.just(w), st.integers(0, (1 << w.value) - 1))
    ),
    st.none() | st.sampled_from(list(params.ValueType)),
    scalings,
)
def test_decode_value_only_raises_remote_protocol_error(
    answer: tuple[pkw.Width, int], vtype: params.ValueType | None, scaling: params.Scaling
) -> None:
    width, raw = answer
    try:
        number = params.decode_value(raw, width, vtype, scaling)
    except RemoteProtocolError:
        return
    assert isinstance(number, int | float)


@FAST
@given(
    values,
    st.none() | st.floats(allow_nan=False, allow_infinity=False),
    st.none() | st.floats(allow_nan=False, allow_infinity=False),
)
def test_check_limits_only_raises_local_protocol_error(
    value: float | int | str, low: float | None, high: float | None
) -> None:
    with contextlib.suppress(LocalProtocolError):
        params.check_limits(value, low, high, "Hz")


# ------------------------------------------------------------------- catalog

yaml_ish = st.text(alphabet=st.sampled_from(list("abn01-:.,[]{}?&*!#|>'\"\n -")), max_size=60)
catalog_fields = st.fixed_dictionaries(
    {},
    optional={
        "name": st.text(max_size=3) | st.integers(),
        "type": st.sampled_from(["u16", "i32", "f32", "text", "x", "1"]),
        "conversion": st.integers(-10, 110) | st.text(max_size=2),
        "scale": st.sampled_from(["0", "1e-3", ".nan", ".inf", "-2", "x"]),
        "min": st.sampled_from(["0", "5", "-1e9", "x"]),
        "max": st.sampled_from(["0", "5", "-1e9", "x"]),
        "writable": st.sampled_from(["true", "no", "1", "[]"]),
        "array": st.integers(-1, 3),
        "verified": st.sampled_from(["true", "false"]),
        "source": st.sampled_from(["s", "t", ""]),
    },
)


@st.composite
def catalog_texts(draw: st.DrawFn) -> str:
    """Catalog-shaped YAML with wrong values here and there."""
    keys = st.sampled_from(
        ["16-13", "1613", "r0021", "p99999", "1-2", "x", "0", "16-13[1]", "70000"]
    )
    lines = [
        f"name: {draw(st.sampled_from(['t', '', '[]', '1']))}",
        f"dialect: {draw(st.sampled_from(['fc', 'uss', 'hitachi-sjpb', 'x']))}",
        "sources: {s: a source}",
        "parameters:",
    ]
    for key in draw(st.lists(keys, max_size=4)):
        fields = draw(catalog_fields)
        lines.append(f"  {key}: {{{', '.join(f'{k}: {v}' for k, v in fields.items())}}}")
    return "\n".join(lines) + "\n" + draw(yaml_ish)


@settings(FAST, max_examples=400)
@given(yaml_ish | st.text(max_size=40) | catalog_texts())
def test_catalog_loader_only_raises_catalog_error(text: str) -> None:
    with contextlib.suppress(CatalogError):
        _parse_catalog(text, "fuzz.yaml")


# ----------------------------------------------- findings of the fuzzers, pinned

USS_PKE_2000 = bytes.fromhex("17D0 0000 0000 0000")  # AK 1, PNU field 2000, page 0
USS_PAGE_66000 = bytes.fromhex("1000 8800 0000 0000")  # AK 1, PNU field 0, page bits a+f = 33


def test_f_pkw_1_pnu_field_above_1999_beside_a_page_index_is_the_peer_s_error() -> None:
    """Once decoded as PNU 2000 and re-encoded differently; now refused as the drive's error."""
    with pytest.raises(RemoteProtocolError, match="PNU field 2000"):
        pkw.decode_response(USS_PKE_2000, USS, IndLayout.USS)


def test_f_pkw_2_a_page_index_making_a_pnu_above_65535_is_the_peer_s_error() -> None:
    """Once decoded as PNU 66000, which no request can name; now refused as the drive's error."""
    with pytest.raises(RemoteProtocolError, match="66000"):
        pkw.decode_response(USS_PAGE_66000, USS, IndLayout.USS)


def test_f_par_1_huge_value_raises_local_protocol_error() -> None:
    with pytest.raises(LocalProtocolError):
        params.encode_value("1e4300", params.ValueType.U16)


def test_f_par_2_f32_beyond_float_range_raises_local_protocol_error() -> None:
    with pytest.raises(LocalProtocolError):
        params.encode_value("1e309", params.ValueType.F32)


def test_f_par_4_f32_overflow_after_scaling_is_refused() -> None:
    with pytest.raises(LocalProtocolError):
        params.encode_value(1e308, params.ValueType.F32, params.Scaling.conversion(-7))


@pytest.mark.parametrize("text", ["? []", "{[]: 0}", "? {a: 1}\n: b"])
def test_f_cat_1_unhashable_key_is_a_catalog_error(text: str) -> None:
    with pytest.raises(CatalogError):
        _parse_catalog(text, "fuzz.yaml")


@pytest.mark.parametrize("text", ["0000-00-00", "a: 2001-13-01"])
def test_f_cat_2_impossible_date_is_a_catalog_error(text: str) -> None:
    with pytest.raises(CatalogError):
        _parse_catalog(text, "fuzz.yaml")


def test_f_cat_3_huge_integer_is_a_catalog_error() -> None:
    with pytest.raises(CatalogError):
        _parse_catalog("1" * 4301, "fuzz.yaml")


def test_f_cat_4_deep_nesting_is_a_catalog_error() -> None:
    with pytest.raises(CatalogError):
        _parse_catalog("[" * 1000 + "]" * 1000, "fuzz.yaml")
