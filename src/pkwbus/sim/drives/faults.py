"""Fault injection on a drive's answer: one uniform draw picks at most one fault."""

from __future__ import annotations

import random
from dataclasses import dataclass

from pkwbus.protocol.buses import Bus
from pkwbus.protocol.serial.telegram import STX, frame
from pkwbus.sim.config import SimFaults

__all__ = ["Answer", "apply", "other_adr", "pick"]

_NOISE = bytes(b for b in range(256) if b != STX)


@dataclass(frozen=True, slots=True)
class Answer:
    """What goes back on the line, and how much later than due (a late answer)."""

    data: bytes
    late: float = 0.0


def pick(faults: SimFaults, rng: random.Random) -> str | None:
    """The fault for this answer, or None."""
    draw = rng.random()
    for kind, p in faults.probabilities():
        if draw < p:
            return kind
        draw -= p
    return None


def apply(
    kind: str,
    telegram: bytes,
    *,
    stale: bytes | None,
    faults: SimFaults,
    protocol: Bus,
    rng: random.Random,
) -> Answer | None:
    """``telegram`` with fault ``kind`` applied; None when nothing is sent."""
    if kind == "drop":
        return None
    if kind == "late":
        return Answer(telegram, faults.late_seconds)
    if kind == "stale":
        return Answer(stale if stale is not None else telegram)
    if kind == "corrupt":
        wrong = telegram[-1] ^ rng.randrange(1, 256)
        return Answer(telegram[:-1] + bytes((wrong,)))
    if kind == "truncate":
        return Answer(telegram[: rng.randrange(1, len(telegram))])
    if kind == "garbage":
        noise = bytes(rng.choice(_NOISE) for _ in range(rng.randrange(1, 9)))
        return Answer(noise + telegram)
    if kind == "wrong_address":
        return Answer(frame(other_adr(protocol, telegram[2]), telegram[3:-1]))
    raise ValueError(f"unknown fault {kind!r}")


def other_adr(protocol: Bus, adr: int) -> int:
    """The ADR byte of a neighbouring address, in the same format and with the same flags."""
    mask = 0x7F if protocol is Bus.FC and adr & 0x80 else 0x1F
    address = adr & mask
    neighbour = address + 1 if address < 30 else address - 1
    return (adr & ~mask & 0xFF) | neighbour
