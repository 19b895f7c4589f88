"""`pkwbus scan`: which addresses answer, with their status words decoded.

With ``--baudrates auto`` (or a list such as ``19200,9600``) it is the
commissioning scan: every baud rate, fastest first, with each parity of
``--parities`` (E, O, N), the response timeout grown by the wire time of an
answer at that rate. A drive is reported at the first setting it answers
at and not asked again at slower ones. An FC drive is also asked its type
(15-40 FC Type, Danfoss FC protocol); a drive that does not say has none.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad options
or a port that cannot be opened.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from typing import Any

from pkwbus import link
from pkwbus.catalog.description import ParameterDescription
from pkwbus.commands.common import (
    DEFAULT_BAUDRATE,
    PROFIBUS,
    CommandError,
    Exit,
    add_drive_options,
    add_line_options,
    build_port,
    build_target,
)
from pkwbus.commands.profibus import scan as dp_scan
from pkwbus.commands.profibus.context import add_dp_options
from pkwbus.commands.scanning import Progress, parse_addresses, report
from pkwbus.link import PortError
from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.outcomes import Answered, Heard, LineFailed
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.sessions.probe import NO_ANSWER, ask_pkw_length
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.notation import durations, limits
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus, address_range
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.length import shown
from pkwbus.protocol.pzd import status_bits
from pkwbus.protocol.serial.telegram import FcAddressFormat
from pkwbus.protocol.values import ValueType

__all__ = ["AUTO_BAUDRATES", "add_parsers", "run_scan"]

# The rates drives of these protocols take (Danfoss FC parameter 8-32; USS), fastest first.
AUTO_BAUDRATES = tuple(sorted((b for b in limits.BAUDRATES if b <= 115200), reverse=True))
PARITIES = ("E", "O", "N")
FC_TYPE_PNU = 1540  # 15-40 FC Type, text
TYPE_TIMEOUT = 0.2  # seconds for the type's answer, on top of its wire time


def add_parsers(sub: Any) -> None:
    scan = sub.add_parser("scan", help="find the addresses that answer")
    add_line_options(scan, timeout=0.05, retries=0)
    add_drive_options(scan, address=False)
    add_dp_options(scan)
    scan.add_argument("--addresses", default=None, help="e.g. 1-126 or 1,2,5-9")
    scan.add_argument(
        "--baudrates",
        default=None,
        help="try several rates, fastest first: 'auto' (115200 down to 1200) or 19200,9600",
    )
    scan.add_argument(
        "--parities",
        default=None,
        help="the parities tried at each rate, e.g. E,N (default: E,O,N with --baudrates,"
        " else --parity)",
    )
    scan.set_defaults(func=run_scan)


def parse_baudrates(text: str) -> list[int]:
    """``auto`` or a comma list of standard rates, tried fastest first."""
    if text.strip().lower() == "auto":
        return list(AUTO_BAUDRATES)
    rates: list[int] = []
    for part in text.split(","):
        try:
            rate = limits.check_baudrate(int(part.strip()))
        except ValueError:
            known = " ".join(str(b) for b in limits.BAUDRATES)
            raise CommandError(
                f"--baudrates: {part.strip()[:40]!r} is not a supported baud rate ({known})"
                " or auto",
                Exit.BAD_INPUT,
            ) from None
        rates.append(rate)
    return sorted(set(rates), reverse=True)


def parse_parities(text: str) -> list[str]:
    found: list[str] = []
    for part in text.upper().split(","):
        if part.strip() not in PARITIES:
            raise CommandError(
                f"--parities: {part.strip()[:40]!r} is not E, O or N", Exit.BAD_INPUT
            )
        found.append(part.strip())
    return list(dict.fromkeys(found))


def _framing(parity: str, stopbits: int) -> str:
    return f"8{parity}{stopbits}"


async def _scan(
    args: argparse.Namespace,
    addresses: list[int],
    settings: list[tuple[int, str]],
    progress: Progress,
) -> list[dict[str, Any]]:
    found: dict[int, dict[str, Any]] = {}
    for step, (baudrate, parity) in enumerate(settings, 1):
        remaining = [a for a in addresses if a not in found]
        if not remaining:
            break
        at = argparse.Namespace(**{**vars(args), "baudrate": baudrate, "parity": parity})
        line = build_port(at)
        # A slow rate needs the time an answer (as long as the probe) takes on the wire.
        targets = {a: build_target(at, a) for a in remaining}
        carriers = {a: SerialCarrier(t) for a, t in targets.items()}
        answer = len(carriers[remaining[0]].probe_telegram())
        line.timeout = min(
            args.timeout + line.link.settings.wire_time(answer), durations.TELEGRAM_TIMEOUT.high
        )
        specs = [DriveSpec(str(a), carrier) for a, carrier in carriers.items()]
        session = LineSession(line, ExchangeWire(line.timeout), specs, retries=args.retries)
        try:
            await session.open()
        except PortError as exc:
            raise CommandError(str(exc), Exit.PORT) from None
        where = f"{baudrate} baud {_framing(parity, args.stopbits)}"
        try:
            for i, address in enumerate(remaining, 1):
                progress.show(
                    f"{where} ({step}/{len(settings)}): address {address}"
                    f" ({i}/{len(remaining)}), {len(found)} found"
                )
                entry = await _probe(args, session, line, targets[address])
                if entry is None:
                    continue
                entry.update(
                    baudrate=baudrate, parity=parity, stopbits=args.stopbits, protocol=args.protocol
                )
                found[address] = entry
                if not args.json:
                    progress.clear()
                    print(_describe_line(entry), flush=True)
        finally:
            await session.close()
    progress.clear()
    return sorted(found.values(), key=lambda e: int(e["address"]))


def _asking_time(args: argparse.Namespace, line: TelegramPort) -> float:
    """Enough for every try of one job, and a margin."""
    retries: int = args.retries
    return line.timeout * (retries + 1) + 0.5


async def _probe(
    args: argparse.Namespace, session: LineSession, line: TelegramPort, target: DriveTarget
) -> dict[str, Any] | None:
    name = str(target.address)
    deadline = asyncio.get_running_loop().time() + _asking_time(args, line)
    result = await session.probe(name, deadline)
    if isinstance(result.outcome, LineFailed):
        raise CommandError(result.outcome.reason, Exit.NO_ANSWER)
    if not isinstance(result.outcome, Heard):
        return None
    word = result.tally.status_word if result.tally is not None else None
    entry: dict[str, Any] = {"address": target.address, "status_word": word, "status": {}}
    if word is not None:
        entry["status"] = status_bits(word, target.profile)
    entry["type"] = await _drive_type(session, line, target)
    if target.protocol is Bus.USS:
        entry["pkw_words"] = await _pkw_words(args, session, line, target)
    return entry


async def _drive_type(session: LineSession, line: TelegramPort, target: DriveTarget) -> str | None:
    """What an FC drive says its type is (15-40), None when it does not say."""
    if target.protocol is not Bus.FC:
        return None
    try:
        req = pkw.read_text(target.dialect, FC_TYPE_PNU, 0)
    except LocalProtocolError:
        return None
    loop = asyncio.get_running_loop()
    deadline = loop.time() + line.timeout + TYPE_TIMEOUT
    outcome = (await session.job(str(target.address), req, deadline)).outcome
    if not isinstance(outcome, Answered):
        return None
    try:
        _, value = (
            ParameterDescription.from_spec(None)
            .with_type(ValueType.TEXT)
            .value_of(outcome.response)
        )
    except RemoteProtocolError:
        return None
    text = str(value).strip()
    return text or None


async def _pkw_words(
    args: argparse.Namespace, session: LineSession, line: TelegramPort, target: DriveTarget
) -> str | None:
    """A USS drive's PKW length as its answer to a word read shows it (None: no answer)."""
    deadline = asyncio.get_running_loop().time() + _asking_time(args, line)
    words = await ask_pkw_length(session, str(target.address), target, deadline=deadline)
    if words == NO_ANSWER:
        return None
    return "4 or 127" if words == "?" else shown(words)


def _describe_line(entry: dict[str, Any]) -> str:
    where = (
        f"address {entry['address']}: {entry['baudrate']} baud"
        f" {_framing(entry['parity'], entry['stopbits'])} {entry['protocol']}"
    )
    if entry["type"]:
        where += f" {entry['type']}"
    if entry.get("pkw_words"):
        where += f", PKW length {entry['pkw_words']}"
    word = entry["status_word"]
    if word is None:
        return f"{where}, answers (no status word)"
    on = " ".join(name for name, value in entry["status"].items() if value) or "-"
    return f"{where}, STW {word:#06x} {on}"


def summary(
    found: list[dict[str, Any]], addresses: int, settings: list[tuple[int, str]], seconds: float
) -> str:
    tried = f"{addresses} address{'es' if addresses != 1 else ''}"
    if len(settings) > 1:
        tried += f" x {len(settings)} settings"
    if not found:
        return f"no drive answered ({tried}, {seconds:.1f} s)"
    groups: dict[str, int] = {}
    for e in found:
        key = f"{e['baudrate']} baud {_framing(e['parity'], e['stopbits'])}"
        groups[key] = groups.get(key, 0) + 1
    at = ", ".join(f"{n} at {key}" for key, n in groups.items())
    drives = "drive" if len(found) == 1 else "drives"
    return f"{len(found)} {drives} found: {at} ({tried}, {seconds:.1f} s)"


def run_scan(args: argparse.Namespace) -> int:
    if args.protocol == PROFIBUS:
        return dp_scan.run_scan(args)
    protocol = Bus(args.protocol)
    low, high = address_range(protocol, FcAddressFormat(args.address_format))
    if args.addresses:
        addresses = parse_addresses(args.addresses, low, high)
    else:
        addresses = list(range(low, high + 1))
    if args.parities is not None:
        parities = parse_parities(args.parities)
    else:
        parities = parse_parities("E,O,N") if args.baudrates is not None else [args.parity]
    if args.baudrates is not None:
        settings = [(b, p) for b in parse_baudrates(args.baudrates) for p in parities]
    else:
        settings = [(args.baudrate or DEFAULT_BAUDRATE, p) for p in parities]
    progress = Progress(sys.stderr, enabled=not args.json and sys.stderr.isatty())
    started = time.monotonic()
    try:
        found = link.run(_scan(args, addresses, settings, progress))
    finally:
        progress.clear()
    return report(
        args.json, found, summary(found, len(addresses), settings, time.monotonic() - started)
    )
