"""`pkwbus ports`: the serial adapters, with the names to put in a configuration."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from pkwbus.commands.common import Exit
from pkwbus.link.adapters import Adapter, list_adapters

__all__ = ["add_parsers", "format_table", "run_ports"]

# The FTDI driver's default; 1 ms is what low_latency asks for.
FAST_LATENCY_MS = 1


def add_parsers(sub: Any) -> None:
    ports = sub.add_parser(
        "ports", help="list serial adapters with their stable /dev/serial/by-id names"
    )
    ports.add_argument("--json", action="store_true", help="machine-readable output")
    ports.set_defaults(func=run_ports)


def run_ports(args: argparse.Namespace) -> int:
    adapters = list_adapters()
    if args.json:
        print(json.dumps([a.as_dict() for a in adapters], indent=1))
        return Exit.OK
    if not adapters:
        print("no serial adapters found", file=sys.stderr)
        return Exit.OK
    print(format_table(adapters))
    return Exit.OK


def format_table(adapters: list[Adapter]) -> str:
    """One block per adapter: the name to configure first, then what identifies it."""
    blocks = []
    for a in adapters:
        lines = [a.stable_name]
        if a.stable_name != a.device:
            lines.append(f"  device:   {a.device} (may change when replugged)")
        what = " ".join(x for x in (a.manufacturer, a.product or a.description) if x)
        if what:
            lines.append(f"  adapter:  {what}")
        if a.usb_id:
            serial = f", serial {a.serial_number}" if a.serial_number else ""
            lines.append(f"  usb:      {a.usb_id}{serial}")
        if a.driver:
            lines.append(f"  driver:   {a.driver}")
        if a.latency_timer_ms is not None:
            hint = (
                f" (each answer may wait up to {a.latency_timer_ms} ms: "
                "set its latency timer to 1 ms, e.g. setserial DEVICE low_latency)"
                if a.latency_timer_ms > FAST_LATENCY_MS
                else ""
            )
            lines.append(f"  latency:  {a.latency_timer_ms} ms{hint}")
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)
