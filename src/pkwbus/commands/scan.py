"""`pkwbus scan`: which addresses answer, with their status words decoded."""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus import limits, link
from pkwbus.commands.common import (
    CommandError,
    Exit,
    add_drive_options,
    add_line_options,
    build_line,
    build_target,
    emit_json,
)
from pkwbus.link import PortError
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import ErrorKind, Failure, Reply
from pkwbus.protocol.buses import address_range
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pzd import status_bits
from pkwbus.protocol.telegram import FcAddressFormat, Protocol, split_block

__all__ = [
    "add_parsers",
    "parse_addresses",
    "run_scan",
]


def add_parsers(sub: Any) -> None:
    scan = sub.add_parser("scan", help="find the addresses that answer")
    add_line_options(scan, timeout=0.05, retries=0)
    add_drive_options(scan, address=False)
    scan.add_argument("--addresses", default=None, help="e.g. 1-126 or 1,2,5-9")
    scan.set_defaults(func=run_scan)


def parse_addresses(text: str, low: int, high: int) -> list[int]:
    """``1-126`` or ``1,2,5-9``, each address ``low``-``high`` (the protocol's range)."""
    try:
        found = limits.parse_addresses(text, low, high)
    except ValueError as exc:
        raise CommandError(f"--addresses: {exc}", Exit.BAD_INPUT) from None
    if not found:
        raise CommandError("--addresses: no address given", Exit.BAD_INPUT)
    return found


async def _scan(args: argparse.Namespace, addresses: list[int]) -> list[dict[str, Any]]:
    line = build_line(args)
    targets = [build_target(args, a) for a in addresses]
    try:
        await line.open()
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    found: list[dict[str, Any]] = []
    try:
        for target in targets:
            for _ in range(args.retries + 1):
                result = await line.exchange(target, target.probe())
                if isinstance(result, Failure) and result.kind is ErrorKind.PORT:
                    raise CommandError(result.detail, Exit.NO_ANSWER)
                if isinstance(result, Reply):
                    found.append(_describe(target.address, target, result))
                    if not args.json:
                        _print(found[-1])
                    break
    finally:
        await line.close()
    return found


def _describe(address: int, target: DriveTarget, reply: Reply) -> dict[str, Any]:
    entry: dict[str, Any] = {"address": address, "status_word": None, "status": {}}
    try:
        block = split_block(reply.data, target.response_shape(len(reply.data)))
    except RemoteProtocolError:
        return entry
    if block.status_word is not None:
        entry["status_word"] = block.status_word
        entry["status"] = status_bits(block.status_word, target.profile)
    return entry


def _print(entry: dict[str, Any]) -> None:
    word = entry["status_word"]
    if word is None:
        print(f"address {entry['address']}: answers (no status word)")
        return
    on = " ".join(name for name, value in entry["status"].items() if value) or "-"
    print(f"address {entry['address']}: STW {word:#06x} {on}")


def run_scan(args: argparse.Namespace) -> int:
    protocol = Protocol(args.protocol)
    low, high = address_range(protocol, FcAddressFormat(args.address_format))
    if args.addresses:
        addresses = parse_addresses(args.addresses, low, high)
    else:
        addresses = list(range(low, high + 1))
    found = link.run(_scan(args, addresses))
    if args.json:
        emit_json(found)
    elif not found:
        print(f"no drive answered on {len(addresses)} addresses")
    return Exit.OK
