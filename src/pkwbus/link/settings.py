"""How a port is opened: its URL, character, start pause, reopen back-off and adapter settings.

Raises: :class:`ValueError` from :class:`PortSettings` for a character
:mod:`pkwbus.protocol.serial.timing` cannot time (a bad parity or stop bits).
"""

from __future__ import annotations

from dataclasses import dataclass

import serial

from pkwbus.errors import PkwbusError
from pkwbus.protocol.serial import timing

__all__ = ["PARITIES", "PortError", "PortSettings", "Rs485Mode"]

PARITIES = {"E": serial.PARITY_EVEN, "O": serial.PARITY_ODD, "N": serial.PARITY_NONE}


class PortError(PkwbusError):
    """The port cannot be opened or was lost."""


@dataclass(frozen=True, slots=True)
class Rs485Mode:
    """Kernel RS-485 mode (pyserial's ``RS485Settings``): RTS levels and delays in seconds."""

    rts_level_for_tx: bool = True
    rts_level_for_rx: bool = False
    delay_before_tx: float = 0.0
    delay_before_rx: float = 0.0


@dataclass(frozen=True, slots=True)
class PortSettings:
    """How to open the port. ``pause`` None = 3.5 character times at ``baudrate``.

    The timing helpers are :mod:`pkwbus.protocol.serial.timing`'s, for these settings.

    ``low_latency`` asks the adapter's driver to pass on received bytes at once
    (an FTDI adapter otherwise holds them up to its 16 ms latency timer); a
    driver that cannot is warned of once and the line runs anyway. ``rs485``
    puts a native UART in kernel RS-485 mode; a driver that refuses it fails
    the open.
    """

    url: str
    baudrate: int = 9600
    parity: str = "E"
    stopbits: int = 1
    pause: float | None = None
    echo: bool = False
    reopen_initial: float = 0.5
    reopen_cap: float = 30.0
    low_latency: bool = False
    rs485: Rs485Mode | None = None

    def __post_init__(self) -> None:
        timing.char_time(self.baudrate, self.parity, self.stopbits)  # ValueError when wrong

    @property
    def char_bits(self) -> int:
        """Bits per character: start, 8 data, parity, stop (11 for 8E1)."""
        return timing.char_bits(self.parity, self.stopbits)

    @property
    def char_time(self) -> float:
        return timing.char_time(self.baudrate, self.parity, self.stopbits)

    @property
    def start_pause(self) -> float:
        return timing.start_pause(self.char_time, self.pause)

    @property
    def inter_char_gap(self) -> float:
        """The default silence that ends a telegram (20 characters, at least 5 ms)."""
        return timing.inter_char_gap(self.char_time)

    def wire_time(self, nbytes: int) -> float:
        return timing.wire_time(nbytes, self.char_time)
