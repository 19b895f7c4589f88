"""The streaming deframer: fed whole, byte by byte and in random chunks, with faults between."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.serial.telegram import (
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
    """A fault and whether a line gap follows it. What the deframer guarantees holds after
    a line gap (a truncated telegram ends in silence) and after bytes without STX; a fault
    directly followed by a telegram is :func:`test_a_damaged_telegram_directly_followed`."""
    wire = draw(valid)
    kind = draw(st.sampled_from(["garbage", "noise", "truncated", "checksum"]))
    if kind == "garbage":
        return draw(no_stx_garbage), False
    if kind == "noise":
        return draw(st.binary(min_size=1, max_size=30)), True
    if kind == "truncated":
        return wire[: draw(st.integers(1, len(wire) - 1))], True
    flip = draw(st.integers(1, 255))
    return wire[:-1] + bytes([wire[-1] ^ flip]), True


# A segment: the telegrams and STX-free garbage that come between two line gaps, and the
# fault (or nothing) that ends it.
Segment = tuple[list[bytes], list[bytes], bytes]


@st.composite
def streams(draw: st.DrawFn) -> list[Segment]:
    """Segments (separated by line gaps) of valid telegrams with faults between them:
    (every piece in order, the valid telegrams, the fault before the gap)."""
    segments: list[Segment] = [([], [], b"")]
    for _ in range(draw(st.integers(1, 12))):
        if draw(st.booleans()):
            fault, gap = draw(faults())
            segments[-1][0].append(fault)
            if gap:
                pieces, telegrams, _ = segments[-1]
                segments[-1] = (pieces, telegrams, fault)
                segments.append(([], [], b""))
        wire = draw(valid)
        segments[-1][0].append(wire)
        segments[-1][1].append(wire)
    return segments


def without_skips(events: list[DeframerEvent]) -> list[DeframerEvent]:
    return [e for e in events if not isinstance(e, Skipped)]


def skipped(events: list[DeframerEvent]) -> int:
    return sum(e.count for e in events if isinstance(e, Skipped))


def at(events: list[DeframerEvent]) -> list[tuple[int, Telegram]]:
    """Each telegram with where it began: the deframer reports every byte once (a
    telegram its own, skipped bytes as a count, a bad candidate its first byte)."""
    out, pos = [], 0
    for event in events:
        if isinstance(event, Telegram):
            out.append((pos, event))
            pos += len(event.data) + 4
        else:
            pos += event.count if isinstance(event, Skipped) else 1
    return out


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges) if b > a]


@settings(max_examples=300)
@given(stream=streams(), cuts=st.lists(st.integers(0, 10_000), max_size=20))
def test_every_valid_telegram_after_a_gap_or_stx_free_bytes_is_recovered(
    stream: list[Segment], cuts: list[int]
) -> None:
    """Between two line gaps, telegrams with STX-free bytes between them are recovered in
    order, however the bytes arrive; what else comes out lies in the fault before the gap
    (random noise may hold a telegram whose BCC is right: no deframer can tell)."""
    d = Deframer(uss_lengths())
    for pieces, expected, fault in stream:
        got = [t.encode() for t in telegrams(feed_all(d, chunked(b"".join(pieces), cuts)))]
        assert got[: len(expected)] == expected
        assert all(extra in fault for extra in got[len(expected) :])


@settings(max_examples=300)
@given(stream=streams(), tail=st.binary(max_size=40))
def test_whole_and_byte_by_byte_agree(stream: list[Segment], tail: bytes) -> None:
    """However the bytes of any stream arrive, the same events come out."""
    for pieces, _, _ in stream:
        data = b"".join(pieces) + tail
        whole = feed_all(Deframer(uss_lengths()), [data])
        single = feed_all(Deframer(uss_lengths()), [data[i : i + 1] for i in range(len(data))])
        assert telegrams(whole) == telegrams(single)
        assert without_skips(whole) == without_skips(single)
        assert skipped(whole) == skipped(single)


@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=10))
def test_any_bytes_give_only_events(data: bytes, cuts: list[int]) -> None:
    d = Deframer(fc_lengths())
    events = feed_all(d, chunked(data, cuts))
    assert all(isinstance(e, Telegram | FramingError) for e in events)
    assert d.buffered == 0
    found = at(events)  # every byte reported once, each telegram where it was
    consumed = sum(
        len(e.data) + 4 if isinstance(e, Telegram) else e.count if isinstance(e, Skipped) else 1
        for e in events
    )
    assert consumed == len(data)
    for start, telegram in found:
        assert data[start : start + len(telegram.data) + 4] == telegram.encode()


damaged_telegrams = st.builds(
    lambda wire, flip: wire[:-1] + bytes([wire[-1] ^ flip]), valid, st.integers(1, 255)
)


@settings(max_examples=300)
@given(damaged=damaged_telegrams, wire=valid, cuts=st.lists(st.integers(0, 100)))
def test_a_damaged_telegram_directly_followed_by_a_valid_one(
    damaged: bytes, wire: bytes, cuts: list[int]
) -> None:
    """Without a gap between them, the telegram after a damaged one is recovered unless the
    hunt inside the damaged bytes finds a telegram that reaches into it and whose one-byte
    XOR BCC happens to be right: a loss no BCC can prevent, and the only one allowed."""
    data = damaged + wire
    found = at(feed_all(Deframer(uss_lengths()), chunked(data, cuts)))
    for start, telegram in found:  # nothing that was not sent, each where it was
        assert data[start : start + len(telegram.data) + 4] == telegram.encode()
    if (len(damaged), Telegram(wire[2], wire[3:-1])) not in found:
        end = len(damaged)
        assert any(0 < s < end < s + len(t.data) + 4 for s, t in found), found


def test_a_false_telegram_in_damaged_bytes_can_hide_the_next_one() -> None:
    """The limit above, made: a damaged telegram holding STX and a length at byte 5, with
    the bytes up to 5 bytes into the next telegram XORing to 0."""
    wire = frame(0x07, bytes(range(12)))
    damaged = bytearray(frame(0x05, bytes([0, 0, 0x02, 14] + [0] * 8)))
    damaged[-1] ^= 0x5A  # the damaged telegram's BCC is wrong
    candidate = bytes(damaged[5:]) + wire[:5]
    x = 0
    for byte in candidate:
        x ^= byte
    damaged[7] ^= x  # inside the false candidate: its XOR is now 0
    damaged_bcc = 0
    for byte in damaged:
        damaged_bcc ^= byte
    assert damaged_bcc != 0  # still a damaged telegram
    events = Deframer(uss_lengths()).feed(bytes(damaged) + wire)
    assert isinstance(events[0], BadChecksum)
    got = [t.encode() for t in telegrams(events)]
    assert got == [bytes(damaged[5:]) + wire[:5]]  # the next telegram is lost
    # After a line gap between them, it is not.
    d = Deframer(uss_lengths())
    feed_all(d, [bytes(damaged)])
    assert [t.encode() for t in telegrams(d.feed(wire))] == [wire]
