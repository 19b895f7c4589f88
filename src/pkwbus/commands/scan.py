"""`pkwbus scan`: which addresses answer, with their status words decoded."""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus import link
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
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pzd import status_bits
from pkwbus.protocol.telegram import Protocol, split_block

ADDRESS_RANGE = {Protocol.FC: (1, 126), Protocol.USS: (0, 30)}


def add_parsers(sub: Any) -> None:
    scan = sub.add_parser("scan", help="find the addresses that answer")
    add_line_options(scan, timeout=0.05, retries=0)
    add_drive_options(scan, address=False)
    scan.add_argument("--addresses", default=None, help="e.g. 1-126 or 1,2,5-9")
    scan.set_defaults(func=run_scan)


def parse_addresses(text: str, low: int, high: int) -> list[int]:
    """``1-126`` or ``1,2,5-9``, each address ``low``-``high`` (the protocol's range)."""
    found: list[int] = []
    for part in text.split(","):
        part = part.strip()
        first_text, sep, last_text = part.partition("-")
        try:
            first, last = int(first_text), int(last_text) if sep else int(first_text)
        except ValueError:
            raise CommandError(
                f"{text[:40]!r} is not a list of addresses like 1-126 or 1,2,5-9", Exit.BAD_INPUT
            ) from None
        if first > last:
            raise CommandError(f"address range {part} runs backwards", Exit.BAD_INPUT)
        for address in (first, last):
            if not low <= address <= high:
                raise CommandError(
                    f"--addresses: {address} is outside {low}-{high}", Exit.BAD_INPUT
                )
        found.extend(range(first, last + 1))
    return sorted(set(found))


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
    if block.pzd:
        entry["status_word"] = block.pzd[0]
        entry["status"] = status_bits(block.pzd[0], target.profile)
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
    low, high = ADDRESS_RANGE[protocol]
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
