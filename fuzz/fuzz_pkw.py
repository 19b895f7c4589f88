"""Fuzz PKW response decoding for every dialect and IND layout, and the transaction state machine.

Properties, per input:
- decode_response raises nothing but RemoteProtocolError;
- a decoded response encodes back to the same PKE and IND, up to the bits
  the decoder does not read (bit 11 of an 11-bit PKE, page bits 0x01/0x02,
  the IND byte beside the subindex where the dialect has no page index);
- PkwTransaction.feed with random replies and failures never raises, and a
  job ends by its (retries + 1)-th failure that counts as a try.

Run: .venv/bin/python fuzz/fuzz_pkw.py -max_total_time=60 var/fuzz/pkw
"""

from __future__ import annotations

import sys

import atheris

with atheris.instrument_imports():
    from pkwbus.master.planning.transaction import ErrorKind, Failure, PkwTransaction, Reply
    from pkwbus.master.target import DriveTarget
    from pkwbus.protocol import pkw
    from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
    from pkwbus.protocol.pkw.dialects import DIALECTS, Command, Dialect, IndLayout

import _support

DIALECT_LIST = tuple(DIALECTS.values())
LAYOUTS = tuple(IndLayout)
KINDS = tuple(ErrorKind)
COUNTED = frozenset(KINDS) - {ErrorKind.UNEXPECTED, ErrorKind.PORT}
COMMANDS = tuple(Command)
PAGE_BITS = 0xFC  # a + 2b + 4c + 8d + 16e + 32f: 0x80 0x10 0x20 0x40 0x04 0x08

# Every finding of these harnesses (see docs/fuzzing.md) is fixed; a new one
# would be listed here while it is open.
KNOWN: tuple[_support.Known, ...] = ()


def split_pke_ind(d: Dialect, layout: IndLayout, pke: int, ind: int) -> tuple[int, int, int]:
    """(PKE bits the decoder reads, subindex, page byte or -1 where the dialect has none)."""
    if layout is IndLayout.USS:
        subindex, other = ind & 0xFF, ind >> 8
    else:
        subindex, other = ind >> 8, ind & 0xFF
    pke_bits = pke if d.pnu_bits == 12 else pke & 0xF7FF
    return pke_bits, subindex, other & PAGE_BITS if d.page_index else -1


def check_roundtrip(data: bytes, d: Dialect, layout: IndLayout) -> None:
    try:
        resp = pkw.decode_response(data, d, layout)
    except RemoteProtocolError:
        return
    words = None if isinstance(resp, pkw.TextResponse) else 3 if len(data) < 8 else 4
    try:
        again = pkw.encode_response(resp, d, layout, words)
        sent = split_pke_ind(d, layout, (data[0] << 8) | data[1], (data[2] << 8) | data[3])
        back = split_pke_ind(d, layout, (again[0] << 8) | again[1], (again[2] << 8) | again[3])
        if sent != back and d.page_index and sent[0] & 0x7FF >= pkw.PAGE_SIZE:
            raise AssertionError(f"F-PKW-1 {data[:4].hex()} -> {again[:4].hex()}")
        assert sent == back, (d.name, layout, data[:4].hex(), again[:4].hex(), resp)
        assert pkw.decode_response(again, d, layout).pnu == resp.pnu
    except (AssertionError, LocalProtocolError) as exc:
        _support.tolerate(exc, KNOWN)


def make_transaction(fdp: atheris.FuzzedDataProvider) -> PkwTransaction | None:
    protocol = "fc" if fdp.ConsumeBool() else "uss"
    d = DIALECT_LIST[fdp.ConsumeIntInRange(0, len(DIALECT_LIST) - 1)]
    try:
        target = DriveTarget.create(
            protocol,
            fdp.ConsumeIntInRange(0, 127),
            dialect_name=d.name,
            ind_layout=LAYOUTS[fdp.ConsumeIntInRange(0, 1)],
            pkw_words=(None, 0, 3, 4)[fdp.ConsumeIntInRange(0, 3)],
            pzd_words=fdp.ConsumeIntInRange(0, 4),
        )
        command = COMMANDS[fdp.ConsumeIntInRange(0, len(COMMANDS) - 1)]
        text = fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 3)) if command is Command.TEXT else b""
        req = pkw.request(
            target.dialect,
            command,
            fdp.ConsumeIntInRange(0, 70000),
            subindex=fdp.ConsumeIntInRange(0, 255),
            value=fdp.ConsumeIntInRange(0, 0xFFFFFFFF),
            text=text,
        )
        return PkwTransaction(
            target, req, retries=fdp.ConsumeIntInRange(0, 5), deadline=fdp.ConsumeIntInRange(1, 40)
        )
    except LocalProtocolError:
        return None


def run_transaction(fdp: atheris.FuzzedDataProvider) -> None:
    job = make_transaction(fdp)
    if job is None:
        return
    target = job.target
    counted = 0
    for step in range(64):
        if fdp.ConsumeBool():
            if fdp.ConsumeBool():  # a well-formed answer to some PNU, maybe the request's
                resp = pkw.ValueResponse(
                    fdp.ConsumeIntInRange(0, 15),
                    job.request.pnu if fdp.ConsumeBool() else fdp.ConsumeIntInRange(0, 3000),
                    job.request.subindex,
                    fdp.ConsumeIntInRange(0, 0xFFFF),
                    pkw.Width.WORD,
                )
                try:
                    body = pkw.encode_response(resp, target.dialect, target.ind_layout, 4)
                except LocalProtocolError:
                    body = b""
                data = body + bytes(2 * target.shape.pzd_words)
            else:
                data = fdp.ConsumeBytes(fdp.ConsumeIntInRange(0, 40))
            result: Reply | Failure = Reply(target.adr, data, 0.01)
        else:
            kind = KINDS[fdp.ConsumeIntInRange(0, len(KINDS) - 1)]
            result = Failure(kind, "fuzz")
            counted += kind in COUNTED
        outcome = job.feed(result, now=float(step))
        if outcome is not None:
            return
        assert counted <= job.retries, (counted, job.retries)
        if not fdp.remaining_bytes():
            return


def test_one_input(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    if fdp.ConsumeBool():
        d = DIALECT_LIST[fdp.ConsumeIntInRange(0, len(DIALECT_LIST) - 1)]
        layout = LAYOUTS[fdp.ConsumeIntInRange(0, 1)]
        check_roundtrip(fdp.ConsumeBytes(fdp.remaining_bytes()), d, layout)
    else:
        run_transaction(fdp)


def main() -> None:
    _support.write_seeds(
        [
            bytes([0, 0, 0]) + bytes.fromhex("1640000000000000"),
            bytes([0, 1, 1]) + bytes.fromhex("20158000000003E8"),
            bytes([0, 0, 0]) + bytes.fromhex("F2BC0004") + b"ABC",
            bytes([1]) + bytes(40),
        ]
    )
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
