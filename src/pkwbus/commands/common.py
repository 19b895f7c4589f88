"""What every bus command shares: exit codes, line and drive options, output.

Raises :class:`CommandError` (a message and an exit code) for options that do not fit.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from collections.abc import Callable
from typing import Any

from pkwbus.catalog import DEFAULT_CATALOGS
from pkwbus.commands.exits import Exit
from pkwbus.errors import PkwbusError
from pkwbus.link import PortSettings
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.notation import durations, limits
from pkwbus.notation.durations import DurationRange, parse_duration
from pkwbus.protocol import buses
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import DIALECTS, IndLayout
from pkwbus.protocol.pkw.length import AUTO, PkwSetting
from pkwbus.protocol.serial.telegram import FcAddressFormat

__all__ = [
    "DEFAULT_BAUDRATE",
    "DEFAULT_CATALOG",
    "PROFIBUS",
    "CommandError",
    "Exit",
    "add_drive_options",
    "add_line_options",
    "baudrate_option",
    "build_port",
    "build_target",
    "duration_option",
    "emit_json",
    "int_option",
    "print_trace",
]


class CommandError(PkwbusError):
    """A failure the user is told about in one line, with its exit code."""

    def __init__(
        self, message: str, code: Exit, *, kind: str = "error", fault: int | None = None
    ) -> None:
        super().__init__(message)
        self.code = code
        self.kind = kind
        self.fault = fault


PROFIBUS = "profibus"  # --protocol profibus: pkwbus as DP-V0 master (commands.dp)
DEFAULT_BAUDRATE = 9600

DEFAULT_CATALOG = {p: DEFAULT_CATALOGS[p.value] for p in (Bus.FC, Bus.USS)}


def duration_option(within: DurationRange) -> Callable[[str], float]:
    """An argparse ``type``: a duration in the range of its kind (``250ms``, ``0.1``, ``2s``)."""

    def duration(text: str) -> float:
        try:
            return parse_duration(text, within)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return duration


def int_option(low: int, high: int) -> Callable[[str], int]:
    """An argparse ``type``: a whole number ``low``-``high``."""

    def whole_number(text: str) -> int:
        try:
            return limits.parse_int(text, low, high)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return whole_number


def baudrate_option(text: str) -> int:
    """An argparse ``type``: one of the standard baud rates."""
    try:
        return limits.check_baudrate(int(text))
    except ValueError:
        known = " ".join(str(b) for b in limits.BAUDRATES)
        raise argparse.ArgumentTypeError(
            f"{text[:40]!r} is not a supported baud rate ({known})"
        ) from None


def add_line_options(
    parser: argparse.ArgumentParser, *, timeout: float = 0.1, retries: int = 2
) -> None:
    g = parser.add_argument_group("line")
    g.add_argument("--port", required=True, help="device path or pyserial URL (socket://...)")
    g.add_argument("--protocol", choices=[p.value for p in Bus], default="fc")
    g.add_argument(
        "--baudrate",
        type=baudrate_option,
        default=None,
        help=f"one of {' '.join(str(b) for b in limits.BAUDRATES)}"
        f" (default {DEFAULT_BAUDRATE}; 19200 for profibus)",
    )
    g.add_argument("--parity", choices=["E", "O", "N"], default="E")
    g.add_argument("--stopbits", type=int, choices=[1, 2], default=1)
    g.add_argument(
        "--timeout",
        type=duration_option(durations.TELEGRAM_TIMEOUT),
        default=timeout,
        help=f"per telegram: 100ms, 0.1 (seconds); {durations.TELEGRAM_TIMEOUT}",
    )
    g.add_argument(
        "--retries",
        type=int_option(0, limits.MAX_RETRIES),
        default=retries,
        help=f"repeats after a missing answer, 0-{limits.MAX_RETRIES}",
    )
    g.add_argument("--echo", action="store_true", help="the adapter hears its own transmission")
    g.add_argument("--trace", action="store_true", help="print every telegram in hex")
    g.add_argument("--json", action="store_true", help="machine-readable output")


def add_drive_options(parser: argparse.ArgumentParser, *, address: bool = True) -> None:
    g = parser.add_argument_group("drive")
    if address:
        g.add_argument("--address", type=int, required=True)
    g.add_argument("--dialect", choices=list(DIALECTS), default=None)
    g.add_argument("--ind-layout", choices=[x.value for x in IndLayout], default=None)
    g.add_argument(
        "--pkw-words", type=_pkw_words, default=AUTO, help="USS: auto (default), 0, 3, 4 or 127"
    )
    g.add_argument("--pzd-words", type=int, default=2, help="USS: 0-16")
    g.add_argument("--address-format", choices=[f.value for f in FcAddressFormat], default="1-126")


def _pkw_words(text: str) -> PkwSetting:
    try:
        return buses.pkw_setting(text, text=True)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_target(args: argparse.Namespace, address: int | None = None) -> DriveTarget:
    try:
        return DriveTarget.create(
            args.protocol,
            args.address if address is None else address,
            dialect_name=args.dialect,
            ind_layout=args.ind_layout,
            pkw_words=args.pkw_words,
            pzd_words=args.pzd_words,
            fc_format=args.address_format,
        )
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None


def build_port(args: argparse.Namespace) -> TelegramPort:
    try:
        settings = PortSettings(
            limits.check_port_url(args.port),
            baudrate=args.baudrate or DEFAULT_BAUDRATE,
            parity=args.parity,
            stopbits=args.stopbits,
            echo=args.echo,
        )
    except ValueError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    trace = _print_trace if args.trace else None
    return TelegramPort(settings, Bus(args.protocol), timeout=args.timeout, trace=trace)


def _print_trace(direction: str, data: bytes) -> None:
    print_trace(direction, data.hex(" "))


def print_trace(direction: str, text: str) -> None:
    """The ``--trace`` printer: a timestamp, the direction and the telegram or the decoded
    frame, on stderr."""
    stamp = datetime.datetime.now().strftime("%H:%M:%S.%f")
    print(f"{stamp} {direction} {text}", file=sys.stderr)


def emit_json(obj: Any) -> None:
    print(json.dumps(obj))
