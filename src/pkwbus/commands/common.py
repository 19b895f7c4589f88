"""What every bus command shares: exit codes, line and drive options, output."""

from __future__ import annotations

import argparse
import datetime
import enum
import json
import sys
from typing import Any

from pkwbus.catalog import DEFAULT_CATALOGS
from pkwbus.link import PortSettings
from pkwbus.master.line import Line
from pkwbus.master.target import DriveTarget
from pkwbus.protocol.dialects import DIALECTS, IndLayout
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.telegram import FcAddressFormat, Protocol


class Exit(enum.IntEnum):
    """The exit codes of interface.md."""

    OK = 0
    REJECTED = 1
    BAD_INPUT = 2
    NO_ANSWER = 3
    PORT = 4


class CommandError(Exception):
    """A failure the user is told about in one line, with its exit code."""

    def __init__(
        self, message: str, code: Exit, *, kind: str = "error", fault: int | None = None
    ) -> None:
        super().__init__(message)
        self.code = code
        self.kind = kind
        self.fault = fault


DEFAULT_CATALOG = {p: DEFAULT_CATALOGS[p.value] for p in Protocol}


def add_line_options(
    parser: argparse.ArgumentParser, *, timeout: float = 0.1, retries: int = 2
) -> None:
    g = parser.add_argument_group("line")
    g.add_argument("--port", required=True, help="device path or pyserial URL (socket://...)")
    g.add_argument("--protocol", choices=[p.value for p in Protocol], default="fc")
    g.add_argument("--baudrate", type=int, default=9600)
    g.add_argument("--parity", choices=["E", "O", "N"], default="E")
    g.add_argument("--stopbits", type=int, choices=[1, 2], default=1)
    g.add_argument("--timeout", type=float, default=timeout, help="seconds per telegram")
    g.add_argument("--retries", type=int, default=retries)
    g.add_argument("--echo", action="store_true", help="the adapter hears its own transmission")
    g.add_argument("--trace", action="store_true", help="print every telegram in hex")
    g.add_argument("--json", action="store_true", help="machine-readable output")


def add_drive_options(parser: argparse.ArgumentParser, *, address: bool = True) -> None:
    g = parser.add_argument_group("drive")
    if address:
        g.add_argument("--address", type=int, required=True)
    g.add_argument("--dialect", choices=list(DIALECTS), default=None)
    g.add_argument("--ind-layout", choices=[x.value for x in IndLayout], default=None)
    g.add_argument("--pkw-words", type=_pkw_words, default=4, help="USS: 0, 3, 4 or 127")
    g.add_argument("--pzd-words", type=int, default=2, help="USS: 0-16")
    g.add_argument("--address-format", choices=[f.value for f in FcAddressFormat], default="1-126")


def _pkw_words(text: str) -> int | None:
    if text in ("127", "variable"):
        return None
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not 0, 3, 4 or 127") from None


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


def build_line(args: argparse.Namespace) -> Line:
    if args.timeout <= 0:
        raise CommandError("--timeout must be positive", Exit.BAD_INPUT)
    if args.retries < 0:
        raise CommandError("--retries must not be negative", Exit.BAD_INPUT)
    try:
        settings = PortSettings(
            args.port,
            baudrate=args.baudrate,
            parity=args.parity,
            stopbits=args.stopbits,
            echo=args.echo,
        )
    except ValueError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    trace = _print_trace if args.trace else None
    return Line(settings, Protocol(args.protocol), timeout=args.timeout, trace=trace)


def _print_trace(direction: str, data: bytes) -> None:
    stamp = datetime.datetime.now().strftime("%H:%M:%S.%f")
    print(f"{stamp} {direction} {data.hex(' ')}", file=sys.stderr)


def emit_json(obj: Any) -> None:
    print(json.dumps(obj))
