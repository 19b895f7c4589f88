"""FDL frames byte-exact, round trips, and the streaming deframer under faults."""

from __future__ import annotations

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.fdl import (
    BadChecksum,
    BadEnd,
    BadFrame,
    BadLength,
    DataFrame,
    Deframer,
    DeframerEvent,
    FrameControl,
    FramingError,
    Function,
    ShortAck,
    Skipped,
    StationType,
    Status,
    Token,
    Truncated,
)

# Captured from a Festo slave 8 with master 2 (pyprofibus issue 19).
CAPTURED = {
    "fdl_status": "10 08 02 49 53 16",
    "fdl_status_answer": "10 02 08 00 0A 16",
    "diag_request": "68 05 05 68 88 82 6D 3C 3E F1 16",
    "diag_not_ready": "68 0B 0B 68 82 88 08 3E 3C 02 05 00 FF 0A 35 D1 16",
    "set_prm": "68 13 13 68 88 82 5D 3D 3E B8 1E 01 00 0A 35 01 00 00 00 82 00 00 00 7B 16",
    "chk_cfg": "68 06 06 68 88 82 7D 3E 3E 21 24 16",
    "diag_ready": "68 0B 0B 68 82 88 08 3E 3C 00 0C 00 02 0A 35 D9 16",
    "rs": "10 02 08 03 0D 16",
}
# Computed from the frame rules (not captured).
COMPUTED = {
    "chk_cfg_ppo1": "68 07 07 68 88 82 7D 3E 3E F3 F1 E7 16",
    "global_control_clear": "68 07 07 68 FF 82 46 3A 3E 02 00 41 16",
    "data_exchange_sd3": "A2 08 02 5D 00 00 00 00 00 00 00 00 67 16",
}
VECTORS = {**CAPTURED, **COMPUTED}

EXPECTED = {
    "fdl_status": DataFrame(8, 2, fdl.request_fc(Function.FDL_STATUS)),
    "fdl_status_answer": DataFrame(2, 8, fdl.response_fc(Status.OK)),
    "diag_request": DataFrame(8, 2, fdl.request_fc(Function.SRD_HIGH, fcb=True), 60, 62),
    "diag_not_ready": DataFrame(
        2, 8, fdl.response_fc(Status.DL), 62, 60, bytes.fromhex("02 05 00 FF 0A 35")
    ),
    "set_prm": DataFrame(
        8,
        2,
        fdl.request_fc(Function.SRD_HIGH, fcv=True),
        61,
        62,
        bytes.fromhex("B8 1E 01 00 0A 35 01 00 00 00 82 00 00 00"),
    ),
    "chk_cfg": DataFrame(
        8, 2, fdl.request_fc(Function.SRD_HIGH, fcb=True, fcv=True), 62, 62, b"\x21"
    ),
    "diag_ready": DataFrame(
        2, 8, fdl.response_fc(Status.DL), 62, 60, bytes.fromhex("00 0C 00 02 0A 35")
    ),
    "rs": DataFrame(2, 8, fdl.response_fc(Status.RS)),
    "chk_cfg_ppo1": DataFrame(
        8, 2, fdl.request_fc(Function.SRD_HIGH, fcb=True, fcv=True), 62, 62, b"\xf3\xf1"
    ),
    "global_control_clear": DataFrame(
        127, 2, fdl.request_fc(Function.SDN_HIGH), 58, 62, b"\x02\x00"
    ),
    "data_exchange_sd3": DataFrame(
        8, 2, fdl.request_fc(Function.SRD_HIGH, fcv=True), data=bytes(8)
    ),
}


@pytest.mark.parametrize("name", sorted(VECTORS))
def test_vector_encodes_and_decodes_byte_exact(name: str) -> None:
    raw = bytes.fromhex(VECTORS[name])
    assert fdl.encode(EXPECTED[name]) == raw
    assert fdl.decode(raw) == EXPECTED[name]


def test_frame_control_fields_of_the_captured_start_up() -> None:
    diag = FrameControl(0x6D)
    assert (diag.is_request, diag.fcb, diag.fcv, diag.function) == (
        True,
        True,
        False,
        Function.SRD_HIGH,
    )
    prm = FrameControl(0x5D)
    assert (prm.fcb, prm.fcv) == (False, True)
    answer = FrameControl(0x08)
    assert (answer.is_request, answer.status, answer.station_type) == (
        False,
        Status.DL,
        StationType.SLAVE,
    )
    assert FrameControl(0x03).status is Status.RS
    assert FrameControl(0x0A).status is Status.DH
    assert FrameControl(0x49).function is Function.FDL_STATUS
    assert FrameControl(0x0F).status is None
    assert FrameControl(0x41).function is None


def test_short_frames() -> None:
    assert fdl.encode(ShortAck()) == b"\xe5"
    assert fdl.decode(b"\xe5") == ShortAck()
    assert fdl.encode(Token(2, 2)) == bytes.fromhex("DC 02 02")
    assert fdl.decode(bytes.fromhex("DC 03 02")) == Token(3, 2)


def test_only_one_sap_present() -> None:
    frame = DataFrame(8, 2, 0x5D, dsap=61, data=b"\x01")
    raw = fdl.encode(frame)
    assert raw[4] == 0x88 and raw[5] == 0x02
    assert fdl.decode(raw) == frame


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (DataFrame(128, 2, 0x5D), "DA 128"),
        (DataFrame(8, -1, 0x5D), "SA -1"),
        (DataFrame(8, 2, 0x5D, dsap=64), "DSAP 64"),
        (DataFrame(8, 2, 0x5D, ssap=-1), "SSAP -1"),
        (DataFrame(8, 2, 256), "FC 256"),
        (DataFrame(8, 2, 0x5D, data=bytes(247)), "do not fit"),
        (Token(2, 200), "token SA 200"),
    ],
)
def test_what_fdl_cannot_say_is_a_local_error(frame: fdl.Frame, message: str) -> None:
    with pytest.raises(LocalProtocolError, match=message):
        fdl.encode(frame)


def test_largest_frame() -> None:
    frame = DataFrame(8, 2, 0x5D, 61, 62, bytes(244))
    raw = fdl.encode(frame)
    assert len(raw) == fdl.MAX_FRAME and raw[1] == fdl.MAX_LE
    assert fdl.decode(raw) == frame


@pytest.mark.parametrize(
    ("raw", "kind"),
    [
        ("10 08 02 49 54 16", BadChecksum),
        ("10 08 02 49 53 17", BadEnd),
        ("68 05 06 68 88 82 6D 3C 3E F1 16", BadLength),
        ("68 05 05 69 88 82 6D 3C 3E F1 16", BadLength),
        ("68 03 03 68 08 02 6D 77 16", BadLength),
        ("10 88 02 49 D3 16", BadFrame),  # DSAP announced in SD1
        ("68 04 04 68 88 82 6D 3C B3 16", BadFrame),  # SSAP announced, missing
        ("68 05 05 68 88 82 6D 7C 3E 31 16", BadFrame),  # segment bit in DSAP
        ("68 05 05 68 88 82 6D 3C", Truncated),
        ("DC 80 02", BadFrame),
    ],
)
def test_peer_errors(raw: str, kind: type[FramingError]) -> None:
    data = bytes.fromhex(raw)
    deframer = Deframer()
    events = deframer.feed(data) + deframer.flush()
    assert isinstance(events[0], kind), events
    assert not any(isinstance(e, fdl.Frame) for e in events)
    with pytest.raises(RemoteProtocolError, match="not one FDL frame"):
        fdl.decode(data)


# ---------------------------------------------------------------- round trip

addresses = st.integers(0, 127)
saps = st.none() | st.integers(0, 63)


@st.composite
def data_frames(draw: st.DrawFn) -> DataFrame:
    dsap, ssap = draw(saps), draw(saps)
    room = fdl.MAX_LE - 3 - (dsap is not None) - (ssap is not None)
    data = draw(st.binary(max_size=room))
    return DataFrame(draw(addresses), draw(addresses), draw(st.integers(0, 255)), dsap, ssap, data)


frames = data_frames() | st.builds(Token, addresses, addresses) | st.just(ShortAck())
checked_frames = data_frames()


@settings(deadline=None)
@given(frames)
def test_round_trip(frame: fdl.Frame) -> None:
    assert fdl.decode(fdl.encode(frame)) == frame


@settings(deadline=None)
@given(data_frames())
def test_fcs_and_lengths(frame: DataFrame) -> None:
    raw = fdl.encode(frame)
    assert raw[-1] == fdl.ED
    start = 4 if raw[0] == fdl.SD2 else 1
    assert raw[-2] == sum(raw[start:-2]) % 256
    if raw[0] == fdl.SD2:
        assert raw[1] == raw[2] == len(raw) - 6 == frame.body_length


# ------------------------------------------------------------------ deframer


def only_frames(events: list[DeframerEvent]) -> list[fdl.Frame]:
    return [e for e in events if isinstance(e, fdl.Frame)]


def feed_chunks(deframer: Deframer, data: bytes, cuts: list[int]) -> list[DeframerEvent]:
    events: list[DeframerEvent] = []
    last = 0
    for cut in [*sorted(c % (len(data) + 1) for c in cuts), len(data)]:
        events += deframer.feed(data[last:cut])
        assert deframer.buffered < fdl.MAX_FRAME
        last = max(last, cut)
    return events


def test_every_vector_whole_and_byte_by_byte() -> None:
    stream = b"".join(bytes.fromhex(VECTORS[n]) for n in sorted(VECTORS))
    expected = [EXPECTED[n] for n in sorted(VECTORS)]
    assert Deframer().feed(stream) == expected
    deframer = Deframer()
    events: list[DeframerEvent] = []
    for i in range(len(stream)):
        events += deframer.feed(stream[i : i + 1])
    assert events == expected
    assert deframer.buffered == 0


def test_garbage_then_frame_is_skipped_once() -> None:
    raw = bytes.fromhex(VECTORS["diag_ready"])
    events = Deframer().feed(b"\x00\x33\x99" + raw)
    assert events == [Skipped(3), EXPECTED["diag_ready"]]


def test_bad_fcs_then_valid_frame() -> None:
    good = bytes.fromhex(VECTORS["set_prm"])
    bad = good[:-2] + bytes(((good[-2] + 1) % 256,)) + good[-1:]
    events = Deframer().feed(bad + good)
    assert events[0] == BadChecksum(bad)
    assert only_frames(events) == [EXPECTED["set_prm"]]


def test_truncated_frame_then_valid_frame_without_a_gap() -> None:
    good = bytes.fromhex(VECTORS["diag_not_ready"])
    events = Deframer().feed(good[:7] + good)
    assert only_frames(events) == [EXPECTED["diag_not_ready"]]


def test_short_ack_and_token_only_in_step() -> None:
    # After garbage an E5 or DC is not trusted: it could be noise.
    deframer = Deframer()
    assert only_frames(deframer.feed(b"\x42\xe5\xdc\x10\x08")) == []
    deframer.flush()
    assert deframer.feed(b"\xe5") == [ShortAck()]
    rs = bytes.fromhex(VECTORS["rs"])
    assert Deframer().feed(rs + b"\xe5" + bytes.fromhex("DC 02 02")) == [
        EXPECTED["rs"],
        ShortAck(),
        Token(2, 2),
    ]


def test_a_token_in_garbage_does_not_eat_the_next_frame() -> None:
    good = bytes.fromhex(VECTORS["fdl_status"])
    events = Deframer().feed(b"\x00\xdc\x05" + good)
    assert only_frames(events) == [EXPECTED["fdl_status"]]


def test_flush_reports_a_truncated_frame_and_empties_the_buffer() -> None:
    deframer = Deframer()
    assert deframer.feed(bytes.fromhex("68 05 05 68 88")) == []
    assert deframer.buffered == 5
    events = deframer.flush()
    assert events[0] == Truncated(bytes.fromhex("68 05 05 68 88"))
    assert deframer.buffered == 0


@settings(deadline=None)
@given(st.lists(frames, min_size=1, max_size=8), st.lists(st.integers(0, 2000), max_size=10))
def test_frames_in_random_chunks(items: list[fdl.Frame], cuts: list[int]) -> None:
    stream = b"".join(fdl.encode(f) for f in items)
    deframer = Deframer()
    assert feed_chunks(deframer, stream, cuts) == items
    assert deframer.buffered == 0


@settings(deadline=None)
@given(
    st.binary(max_size=600),
    st.lists(checked_frames, min_size=1, max_size=4),
    st.lists(st.integers(0, 2000), max_size=10),
)
def test_garbage_then_checked_frames_without_a_gap(
    garbage: bytes, items: list[DataFrame], cuts: list[int]
) -> None:
    """Garbage of any kind, then valid frames: every frame is found, none invented after it.

    Except garbage that leaves the line in step with a token begun (the
    deframer holds a lone SD4, or SD4 and DA): the frame's first bytes
    complete that token (see the test after this one)."""
    alone = Deframer()
    alone.feed(garbage)
    assume(not (alone.buffered and garbage[-alone.buffered] == fdl.SD4))
    stream = garbage + b"".join(fdl.encode(f) for f in items)
    deframer = Deframer()
    events = feed_chunks(deframer, stream, cuts) + deframer.flush()
    found = only_frames(events)
    assert found[len(found) - len(items) :] == items
    assert deframer.buffered == 0


def test_a_token_begun_in_step_takes_the_next_two_bytes() -> None:
    """SD4 carries nothing to check: in step, DC and the next two bytes are a token,
    whatever frame those bytes began."""
    frame = DataFrame(0, 0, 0)
    events = Deframer().feed(b"\xdc" + fdl.encode(frame))
    assert events[0] == Token(fdl.SD1, 0)
    assert frame not in only_frames(events)


@settings(deadline=None)
@given(
    st.binary(max_size=600),
    st.lists(frames, min_size=1, max_size=4),
    st.lists(st.integers(0, 2000), max_size=10),
)
def test_garbage_a_gap_then_any_frames(
    garbage: bytes, items: list[fdl.Frame], cuts: list[int]
) -> None:
    deframer = Deframer()
    before = feed_chunks(deframer, garbage, cuts) + deframer.flush()
    assert all(isinstance(e, fdl.Frame | FramingError) for e in before)
    assert deframer.buffered == 0
    after = feed_chunks(deframer, b"".join(fdl.encode(f) for f in items), cuts)
    assert after == items


@settings(deadline=None)
@given(st.binary(max_size=1200), st.lists(st.integers(0, 2000), max_size=20))
def test_chunking_does_not_change_the_frames(data: bytes, cuts: list[int]) -> None:
    whole = Deframer()
    expected = only_frames(whole.feed(data) + whole.flush())
    chunked = Deframer()
    got = only_frames(feed_chunks(chunked, data, cuts) + chunked.flush())
    assert got == expected
