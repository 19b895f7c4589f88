"""PROFIBUS DP bus timing in bit times, and what it comes to in seconds: pure arithmetic.

Up to 187.5 kbit/s the defaults are (EN 50170 vol. 2 part 4, section 4.4,
"timers"; Felser PROFIBUS manual, "bus parameters"): an idle time TSYN of 33
bit times before every request, the slave's earliest reply min TSDR 11, its
latest max TSDR 60, the slot time TSL 100, and after an answer TID1 = 37 bit
times before the master's next request (after a broadcast TID2 = max TSDR).
A character is 11 bits (start, 8 data, even parity, stop).

A USB adapter delivers received bytes late (its latency timer), so a master
behind one needs a slot time of milliseconds, not 100 bit times: 30 ms at
19.2 kbit/s and 8 ms at 93.75 kbit/s are safe (profirust, serial PHY notes).
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "CHAR_BITS",
    "MAX_TSDR_BITS",
    "MIN_TSDR_BITS",
    "TID1_BITS",
    "TSL_BITS",
    "TSYN_BITS",
    "TTO_SLOTS",
    "USB_SLOT_FAST",
    "USB_SLOT_MIDDLE",
    "USB_SLOT_SLOW",
    "bits",
    "default_slot_time",
    "exchange_time",
    "token_lost_time",
    "wire_time",
]

CHAR_BITS: Final = 11
TSYN_BITS: Final = 33
TID1_BITS: Final = 37
MIN_TSDR_BITS: Final = 11
MAX_TSDR_BITS: Final = 60
TSL_BITS: Final = 100
TTO_SLOTS: Final = 6  # token-lost time: 6 slot times + 2 per station address

# Slot times safe over USB adapters (seconds), by baud rate.
USB_SLOT_SLOW: Final = 0.030  # up to 19.2 kbit/s
USB_SLOT_MIDDLE: Final = 0.015  # between (45.45 kbit/s) [check per adapter]
USB_SLOT_FAST: Final = 0.008  # 93.75 kbit/s and above


def bits(count: float, baudrate: int) -> float:
    """Seconds ``count`` bit times take at ``baudrate``."""
    if baudrate <= 0:
        raise ValueError(f"baud rate {baudrate} is not positive")
    return count / baudrate


def wire_time(nbytes: int, baudrate: int) -> float:
    """Seconds ``nbytes`` characters take on the line."""
    return bits(nbytes * CHAR_BITS, baudrate)


def default_slot_time(baudrate: int, max_tsdr: int | None = None) -> float:
    """A slot time safe over a USB-RS485 adapter, never below the standard 100 bit times.

    It allows a slave the standard max TSDR of 60 bit times; ``max_tsdr``, the
    longest any slave's GSD file gives at this rate (``MaxTsdr_<rate>``), adds
    what it asks beyond that."""
    if baudrate <= 19200:
        usb = USB_SLOT_SLOW
    elif baudrate < 93750:
        usb = USB_SLOT_MIDDLE
    else:
        usb = USB_SLOT_FAST
    beyond = bits(max(0, (max_tsdr or 0) - MAX_TSDR_BITS), baudrate)
    return max(usb, bits(TSL_BITS, baudrate)) + beyond


def token_lost_time(slot_time: float, address: int) -> float:
    """TTO: how long a master listens before it may go active (6 + 2 x address slot times)."""
    return (TTO_SLOTS + 2 * address) * slot_time


def exchange_time(request: int, answer: int, baudrate: int) -> float:
    """One request/answer cycle at best: request, TSYN, min TSDR, answer, TID1."""
    total = (request + answer) * CHAR_BITS + TSYN_BITS + MIN_TSDR_BITS + TID1_BITS
    return bits(total, baudrate)
