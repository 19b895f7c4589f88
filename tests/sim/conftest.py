"""Helpers for the simulator tests: a fake clock and request builders using the protocol core."""

from __future__ import annotations

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw import PkwRequest
from pkwbus.protocol.pkw.dialects import Dialect, IndLayout
from pkwbus.protocol.serial.telegram import Telegram, encode_block, frame


class FakeClock:
    def __init__(self, now: float = 1000.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


def request_telegram(
    adr: int,
    req: PkwRequest,
    d: Dialect,
    layout: IndLayout | None = None,
    pkw_words: int | None = 4,
    pzd: tuple[int, ...] = (0, 0),
) -> bytes:
    data = pkw.encode_request(req, d, layout or d.default_ind_layout, pkw_words)
    return frame(adr, encode_block(data, pzd))


def parse(answer: bytes | None) -> Telegram:
    assert answer is not None, "the simulator did not answer"
    assert answer[0] == 0x02 and answer[1] == len(answer) - 2
    acc = 0
    for byte in answer:
        acc ^= byte
    assert acc == 0, "bad BCC"
    return Telegram(answer[2], answer[3:-1])
