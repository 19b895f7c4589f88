"""Fuzz the streaming deframer (FC and USS lengths) with random bytes in random chunks.

Properties, per input:
- feed/flush return only Telegram and FramingError events;
- after every feed at most 256 bytes stay buffered, after a flush none;
- garbage, then a gap on the line (flush), then a valid telegram, then a gap,
  yields exactly that telegram;
- the telegrams found do not depend on how the bytes were chunked.

Run: .venv/bin/python fuzz/fuzz_deframer.py -max_total_time=60 var/fuzz/deframer
"""

from __future__ import annotations

import sys

import atheris

with atheris.instrument_imports():
    from pkwbus.protocol.serial.telegram import (
        FC_PARAMETER,
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

import _support

LENGTH_SETS = (
    fc_lengths(),
    uss_lengths(),
    uss_lengths([USS_DEFAULT]),
    uss_lengths([FC_PARAMETER, BlockShape(3, 2), BlockShape(0, 6)]),
)
SORTED_LENGTHS = tuple(sorted(s) for s in LENGTH_SETS)


def chunks(fdp: atheris.FuzzedDataProvider, data: bytes) -> list[bytes]:
    """Cut ``data`` into pieces of sizes drawn from the input (1..64 bytes)."""
    out: list[bytes] = []
    pos = 0
    while pos < len(data):
        size = fdp.ConsumeIntInRange(1, 64) if fdp.remaining_bytes() else len(data) - pos
        out.append(data[pos : pos + size])
        pos += size
    return out


def feed(deframer: Deframer, pieces: list[bytes]) -> list[DeframerEvent]:
    events: list[DeframerEvent] = []
    for piece in pieces:
        got = deframer.feed(piece)
        assert deframer.buffered <= MAX_TELEGRAM, deframer.buffered
        events += got
    return events


def check_events(events: list[DeframerEvent]) -> None:
    for event in events:
        assert isinstance(event, Telegram | FramingError), event


def without_skips(events: list[DeframerEvent]) -> tuple[list[DeframerEvent], int]:
    kept = [e for e in events if not isinstance(e, Skipped)]
    return kept, sum(e.count for e in events if isinstance(e, Skipped))


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    which = fdp.ConsumeIntInRange(0, len(LENGTH_SETS) - 1)
    lengths = LENGTH_SETS[which]
    lge = SORTED_LENGTHS[which][fdp.ConsumeIntInRange(0, len(SORTED_LENGTHS[which]) - 1)]
    adr = fdp.ConsumeIntInRange(0, 255)
    body = fdp.ConsumeBytes(lge - 2).ljust(lge - 2, b"\x00")
    valid = frame(adr, body)
    garbage = fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 700))

    # Garbage in chunks, a gap, the valid telegram in chunks, a gap.
    deframer = Deframer(lengths)
    before = feed(deframer, chunks(fdp, garbage))
    before += deframer.flush()
    assert deframer.buffered == 0
    check_events(before)
    after = feed(deframer, chunks(fdp, valid))
    after += deframer.flush()
    check_events(after)
    assert after == [Telegram(adr, body)], (garbage.hex(), valid.hex(), after)

    # Chunking does not change what is found: whole versus chunked versus byte by byte.
    stream = garbage + valid + fdp.ConsumeBytes(fdp.remaining_bytes() // 2)
    whole_d = Deframer(lengths)
    whole = whole_d.feed(stream) + whole_d.flush()
    chunked_d = Deframer(lengths)
    chunked = feed(chunked_d, chunks(fdp, stream)) + chunked_d.flush()
    check_events(whole)
    check_events(chunked)
    assert without_skips(whole) == without_skips(chunked), stream.hex()


def main() -> None:
    _support.write_seeds(
        [
            bytes([0, 10, 0x81]) + bytes.fromhex("020E01164E0000000000000000000055"),
            b"\x02\x0e\x02\x02\x02" + b"\x00" * 40,
            b"\x01\x05\x07" + b"\x02" * 200,
        ]
    )
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
