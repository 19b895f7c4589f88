"""Fuzz the PROFIBUS FDL deframer, the DP decoders and the GSD reader with random bytes.

Properties, per input:
- feed/flush return only Frame and FramingError events; fewer than 255 bytes
  stay buffered after every feed, none after a flush;
- garbage, then a gap on the line (flush), then a valid frame, then a gap,
  yields exactly that frame;
- decode_diagnosis, parse_cfg, decode_parameters and decode_ppo_read raise
  only RemoteProtocolError; gsd.parse raises only GsdError.

Run: .venv/bin/python fuzz/fuzz_fdl.py -max_total_time=60 var/fuzz/fdl/corpus
"""

from __future__ import annotations

import contextlib
import sys

import atheris

with atheris.instrument_imports():
    from pkwbus.protocol.errors import RemoteProtocolError
    from pkwbus.protocol.profibus import fdl, gsd
    from pkwbus.protocol.profibus.dp import ppo
    from pkwbus.protocol.profibus.dp import services as dp_services

import _support

SEEDS = [
    bytes.fromhex("10 08 02 49 53 16"),
    bytes.fromhex("68 0B 0B 68 82 88 08 3E 3C 02 05 00 FF 0A 35 D1 16"),
    bytes.fromhex("A2 08 02 5D 00 00 00 00 00 00 00 00 67 16"),
    b'#Profibus_DP\nIdent_Number = 0x0402\nModule = "PPO 1" 0xF3,0xF1\nEndModule\n',
]


def chunks(fdp: atheris.FuzzedDataProvider, data: bytes) -> list[bytes]:
    out: list[bytes] = []
    pos = 0
    while pos < len(data):
        size = fdp.ConsumeIntInRange(1, 64) if fdp.remaining_bytes() else len(data) - pos
        out.append(data[pos : pos + size])
        pos += size
    return out


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    payload = fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 240))
    frame = fdl.DataFrame(
        fdp.ConsumeIntInRange(0, 127),
        fdp.ConsumeIntInRange(0, 127),
        fdp.ConsumeIntInRange(0, 255),
        data=payload,
    )
    garbage = fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 700))
    deframer = fdl.Deframer()
    for piece in chunks(fdp, garbage):
        for event in deframer.feed(piece):
            assert isinstance(event, fdl.Frame | fdl.FramingError), event
        assert deframer.buffered < fdl.MAX_FRAME
    deframer.flush()
    assert deframer.buffered == 0
    got: list[fdl.DeframerEvent] = []
    for piece in chunks(fdp, fdl.encode(frame)):
        got += deframer.feed(piece)
    got += deframer.flush()
    assert got == [frame], (garbage.hex(), got)

    for decoder in (
        dp_services.decode_diagnosis,
        dp_services.parse_cfg,
        dp_services.decode_parameters,
        lambda raw: ppo.decode_ppo_read(ppo.ppo_type(1), ppo.dp_dialect("profidrive"), raw),
    ):
        with contextlib.suppress(RemoteProtocolError):
            decoder(garbage)
    with contextlib.suppress(gsd.GsdError):
        gsd.parse(garbage.decode("latin-1"))


def main() -> None:
    _support.write_seeds(SEEDS)
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
