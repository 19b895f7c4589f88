"""The streaming deframer: fed whole, byte by byte and in random chunks, with faults between."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.telegram import (
    BadChecksum,
    BadLength,
    Deframer,
    DeframerEvent,
    FramingError,
    Skipped,
    Telegram,
    Truncated,
    fc_lengths,
    frame,
    uss_lengths,
)

FC_WIRE = bytes.fromhex("02 0E 01 16 4E 00 00 00 00 00 00 00 00 00 00 55")


def telegrams(events: list[DeframerEvent]) -> list[Telegram]:
    return [e for e in events if isinstance(e, Telegram)]


def feed_all(deframer: Deframer, chunks: list[bytes], *, flush: bool = True) -> list[DeframerEvent]:
    out: list[DeframerEvent] = []
    for chunk in chunks:
        out += deframer.feed(chunk)
    if flush:
        out += deframer.flush()
    return out


def test_one_telegram_whole_and_byte_by_byte() -> None:
    whole = Deframer(fc_lengths()).feed(FC_WIRE)
    assert whole == [Telegram(0x01, FC_WIRE[3:-1])]
    d = Deframer(fc_lengths())
    events: list[DeframerEvent] = []
    for i in range(len(FC_WIRE)):
        events += d.feed(FC_WIRE[i : i + 1])
        if i < len(FC_WIRE) - 1:
            assert events == []
    assert events == whole
    assert d.buffered == 0


def test_garbage_before_a_telegram_is_skipped() -> None:
    events = Deframer(fc_lengths()).feed(b"\xff\x00\x13" + FC_WIRE)
    assert events == [Skipped(3), Telegram(0x01, FC_WIRE[3:-1])]


def test_bad_checksum_then_valid() -> None:
    bad = FC_WIRE[:-1] + b"\x00"
    events = Deframer(fc_lengths()).feed(bad + FC_WIRE)
    assert isinstance(events[0], BadChecksum)
    assert events[0].raw == bad
    assert telegrams(events) == [Telegram(0x01, FC_WIRE[3:-1])]


def test_impossible_length() -> None:
    events = Deframer(fc_lengths()).feed(b"\x02\x08" + FC_WIRE)
    assert events[0] == BadLength(8)
    assert telegrams(events) == [Telegram(0x01, FC_WIRE[3:-1])]


def test_truncated_telegram_then_valid_at_a_gap() -> None:
    d = Deframer(fc_lengths())
    assert d.feed(FC_WIRE[:9]) == []
    events = d.flush()
    assert events[0] == Truncated(FC_WIRE[:9])
    assert telegrams(events) == []
    assert d.buffered == 0
    assert d.feed(FC_WIRE) == [Telegram(0x01, FC_WIRE[3:-1])]


def test_truncated_telegram_then_valid_without_gap() -> None:
    events = Deframer(fc_lengths()).feed(FC_WIRE[:9] + FC_WIRE + FC_WIRE)
    assert len(telegrams(events)) >= 1
    assert telegrams(events)[-1] == Telegram(0x01, FC_WIRE[3:-1])


def test_a_long_false_start_does_not_hide_a_telegram_at_the_gap() -> None:
    # An STX in the noise claims 200 bytes; the real telegram follows, then silence.
    d = Deframer(fc_lengths())
    assert d.feed(b"\x02\xc8\x11" + FC_WIRE) == []
    events = d.flush()
    assert isinstance(events[0], Truncated)
    assert telegrams(events) == [Telegram(0x01, FC_WIRE[3:-1])]


def test_the_buffer_is_bounded() -> None:
    d = Deframer(fc_lengths())
    for _ in range(100):
        d.feed(bytes(range(3, 250)))
    assert d.buffered == 0
    d.feed(b"\x02\xfe" + bytes(200))  # an incomplete 256-byte candidate
    assert d.buffered <= 256
    d.feed(bytes(100))
    assert d.buffered < 256


def test_reset_forgets_partial_input() -> None:
    d = Deframer(fc_lengths())
    d.feed(FC_WIRE[:5])
    d.reset()
    assert d.feed(FC_WIRE) == [Telegram(0x01, FC_WIRE[3:-1])]


# ------------------------------------------------------------ properties

adrs = st.integers(0, 255)
uss_data = st.binary(min_size=12, max_size=12)  # PKW 4 + PZD 2
valid = st.builds(lambda a, d: frame(a, d), adrs, uss_data)
no_stx_garbage = st.binary(min_size=1, max_size=30).map(lambda b: b.replace(b"\x02", b"\x03"))


@st.composite
def faults(draw: st.DrawFn) -> tuple[bytes, bool]:
    """A fault and whether a line gap must follow it (a truncation ends in silence)."""
    wire = draw(valid)
    kind = draw(st.sampled_from(["garbage", "noise", "truncated", "checksum"]))
    if kind == "garbage":
        return draw(no_stx_garbage), False
    if kind == "noise":
        return draw(st.binary(min_size=1, max_size=30)), True
    if kind == "truncated":
        return wire[: draw(st.integers(1, len(wire) - 1))], True
    flip = draw(st.integers(1, 255))
    return wire[:-1] + bytes([wire[-1] ^ flip]), False


@st.composite
def streams(draw: st.DrawFn) -> tuple[list[list[bytes]], list[bytes]]:
    """Segments (separated by line gaps) of valid telegrams with faults between them."""
    segments: list[list[bytes]] = [[]]
    expected: list[bytes] = []
    for _ in range(draw(st.integers(1, 12))):
        if draw(st.booleans()):
            fault, gap = draw(faults())
            segments[-1].append(fault)
            if gap:
                segments.append([])
        wire = draw(valid)
        segments[-1].append(wire)
        expected.append(wire)
    return segments, expected


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges) if b > a]


@settings(max_examples=300)
@given(stream=streams(), cuts=st.lists(st.integers(0, 10_000), max_size=20))
def test_every_valid_telegram_is_recovered(
    stream: tuple[list[list[bytes]], list[bytes]], cuts: list[int]
) -> None:
    segments, expected = stream
    d = Deframer(uss_lengths())
    got: list[Telegram] = []
    for segment in segments:
        data = b"".join(segment)
        got += telegrams(feed_all(d, chunked(data, cuts)))
    assert [t.encode() for t in got] == expected


@settings(max_examples=300)
@given(stream=streams())
def test_whole_and_byte_by_byte_agree(stream: tuple[list[list[bytes]], list[bytes]]) -> None:
    segments, _ = stream
    for segment in segments:
        data = b"".join(segment)
        whole = feed_all(Deframer(uss_lengths()), [data])
        single = feed_all(Deframer(uss_lengths()), [data[i : i + 1] for i in range(len(data))])
        assert telegrams(whole) == telegrams(single)


@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=10))
def test_any_bytes_give_only_events(data: bytes, cuts: list[int]) -> None:
    d = Deframer(fc_lengths())
    events = feed_all(d, chunked(data, cuts))
    assert all(isinstance(e, Telegram | FramingError) for e in events)
    assert d.buffered == 0
    consumed = sum(
        len(e.data) + 4 if isinstance(e, Telegram) else e.count if isinstance(e, Skipped) else 0
        for e in events
    )
    assert consumed <= len(data)
