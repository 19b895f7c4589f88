"""Character and telegram timing on an RS-485 line: pure arithmetic, one home.

A character is a start bit, 8 data bits, a parity bit unless the parity is N,
and 1 or 2 stop bits: 11 bits with the 8E1 both Danfoss and Siemens default to
(Danfoss FC 100 Design Manual, port parameters; SINAMICS S110 function manual,
USS). Before each request the line stays quiet for a start pause: USS asks for
at least 2 character times (SINAMICS CU230P-2 and G120P manuals, timing);
pkwbus waits 3.5. A receiver takes a silence of :data:`INTER_CHAR_GAP_CHARS`
character times inside a telegram, and never less than
:data:`MIN_INTER_CHAR_GAP`, as its end: wider than the start pause so that a
USB adapter's delivery jitter does not cut an answer in two.

Nothing here raises except :func:`char_bits`, :class:`ValueError` for a parity
other than E, O or N, stop bits other than 1 or 2, or a baud rate that is not
positive.
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "DEFAULT_CHAR_BITS",
    "INTER_CHAR_GAP_CHARS",
    "MIN_INTER_CHAR_GAP",
    "PARITY_BITS",
    "START_PAUSE_CHARS",
    "char_bits",
    "char_time",
    "inter_char_gap",
    "start_pause",
    "wire_time",
]

PARITY_BITS: Final = {"E": 1, "O": 1, "N": 0}
START_PAUSE_CHARS: Final = 3.5
INTER_CHAR_GAP_CHARS: Final = 20.0
MIN_INTER_CHAR_GAP: Final = 0.005  # seconds
DEFAULT_CHAR_BITS: Final = 11  # 8E1


def char_bits(parity: str = "E", stopbits: int = 1) -> int:
    """Bits per character: start, 8 data, parity unless N, stop bits (11 for 8E1)."""
    if parity not in PARITY_BITS:
        raise ValueError(f"parity {parity!r} is not E, O or N")
    if stopbits not in (1, 2):
        raise ValueError(f"stop bits {stopbits} is not 1 or 2")
    return 1 + 8 + PARITY_BITS[parity] + stopbits


def char_time(baudrate: int, parity: str = "E", stopbits: int = 1) -> float:
    """Seconds one character takes on the line."""
    if baudrate <= 0:
        raise ValueError(f"baud rate {baudrate} is not positive")
    return char_bits(parity, stopbits) / baudrate


def wire_time(nbytes: int, character: float) -> float:
    """Seconds ``nbytes`` take at ``character`` seconds a character."""
    return nbytes * character


def start_pause(character: float, pause: float | None = None) -> float:
    """The quiet time before a request: ``pause`` when given, else 3.5 characters."""
    return pause if pause is not None else START_PAUSE_CHARS * character


def inter_char_gap(character: float, timeout: float | None = None) -> float:
    """The silence that ends a telegram: ``timeout`` when given, else 20 characters,
    at least 5 ms."""
    if timeout is not None:
        return timeout
    return max(MIN_INTER_CHAR_GAP, INTER_CHAR_GAP_CHARS * character)
