"""`pkwbus scan --protocol profibus`: the live list of a DP line.

After listening for other masters (none may be active), pkwbus asks every
address 0-125 but its own for its FDL status (EN 50170 vol. 2 part 4, "FDL
status"): the answer says whether a station is there and whether it is a
slave or a master. Each slave is then asked its diagnosis (Slave_Diag):
ident number, state, and the master that owns it. Nothing is parametrised.
The line runner does it, over the live list's wire
(:class:`~pkwbus.master.wires.profibus.live_list.LiveListWire`); this command
shows what the line's events tell.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad options,
a port that cannot be opened or a line another master runs.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from collections.abc import Sequence
from typing import Any

from pkwbus import link
from pkwbus.commands.common import CommandError, Exit
from pkwbus.commands.profibus.context import DEFAULT_BAUDRATE, MAX_DP_RETRIES, fdl_port
from pkwbus.commands.scanning import Progress, parse_addresses, report
from pkwbus.link import PortError
from pkwbus.master.events import Event, LineState, StationAsked, StationFound, StationsAsked
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.wires.profibus.live_list import LiveListWire
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.fdl import StationType

__all__ = ["run_scan", "slave_state"]

STATION_TYPES = {
    StationType.SLAVE: "slave",
    StationType.MASTER_NOT_READY: "master (not ready)",
    StationType.MASTER_READY: "master (ready)",
    StationType.MASTER_IN_RING: "master (in the ring)",
}


def slave_state(diag: dps.Diagnosis) -> str:
    """The state a diagnosis shows: wait_prm, wait_cfg or data_exchange."""
    if "prm_required" in diag.flags:
        return "wait_prm"
    if not diag.ready:
        return "wait_cfg"
    return "data_exchange"


def _entry(found: StationFound) -> dict[str, Any]:
    entry: dict[str, Any] = {
        "address": found.address,
        "station_type": STATION_TYPES[found.station_type],
    }
    if found.station_type is not StationType.SLAVE:
        return entry
    entry.update(ident=None, state=None, master=None, flags=[])
    diag = found.diagnosis
    if diag is not None:
        entry.update(
            ident=diag.ident, state=slave_state(diag), master=diag.master, flags=sorted(diag.flags)
        )
    return entry


class _LiveList:
    """What the line's events tell of the live list: progress, stations, its end."""

    def __init__(self, json: bool, progress: Progress) -> None:
        self.json = json
        self.progress = progress
        self.found: list[dict[str, Any]] = []
        self.over: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.lost: LineState | None = None  # the line given up or lost while asking

    def on_events(self, events: Sequence[Event]) -> None:
        for event in events:
            if isinstance(event, StationAsked):
                self.progress.show(
                    f"address {event.address} ({event.place}/{event.count}),"
                    f" {len(self.found)} found"
                )
            elif isinstance(event, StationFound):
                entry = _entry(event)
                self.found.append(entry)
                if not self.json and not self.over.done():
                    self.progress.clear()
                    try:
                        print(_describe(entry), flush=True)
                    except BrokenPipeError as exc:  # its reader went away: the scan ends
                        self.over.set_exception(exc)
            elif isinstance(event, StationsAsked) and not self.over.done():
                self.over.set_result(None)
            elif isinstance(event, LineState) and not event.up and event.error:
                self.lost = self.lost or event
                if not self.over.done():
                    self.over.set_result(None)


def _describe(entry: dict[str, Any]) -> str:
    text = f"address {entry['address']}: {entry['station_type']}"
    if entry["station_type"] != "slave":
        return text
    if entry["ident"] is None:
        return f"{text}, no diagnosis"
    owner = "no master" if entry["master"] is None else f"owned by master {entry['master']}"
    return f"{text}, ident {entry['ident']:#06x}, {entry['state']}, {owner}"


async def _scan(
    args: argparse.Namespace, addresses: list[int], progress: Progress
) -> list[dict[str, Any]]:
    line = fdl_port(args)
    watch = _LiveList(args.json, progress)
    wire = LiveListWire(line.master, addresses, tries=args.retries + 1)
    session = LineSession(line, wire, [], retries=args.retries, observers=[watch])
    progress.show(f"listening for other masters ({line.token_lost_time():.2f} s)")
    try:
        await session.open()
        await session.until(watch.over)
    except PortError as exc:
        if watch.lost is None or not watch.lost.refused:  # the port, not another master
            raise CommandError(str(exc), Exit.PORT) from None
    finally:
        progress.clear()
        await session.close()
    lost = watch.lost
    if lost is not None:  # another master heard (the line refused), or the port lost
        kind = "line_error" if lost.refused else "error"
        raise CommandError(lost.error or "the line was lost", Exit.NO_ANSWER, kind=kind)
    return watch.found


def summary(found: list[dict[str, Any]], addresses: int, seconds: float) -> str:
    tried = f"{addresses} address{'es' if addresses != 1 else ''}"
    if not found:
        return f"no station answered ({tried}, {seconds:.1f} s)"
    slaves = sum(1 for e in found if e["station_type"] == "slave")
    masters = len(found) - slaves
    parts = [f"{slaves} slave{'s' if slaves != 1 else ''}"]
    if masters:
        parts.append(f"{masters} master{'s' if masters != 1 else ''}")
    owned = sum(1 for e in found if e.get("master") is not None)
    if owned:
        parts.append(f"{owned} owned by a master")
    return f"{len(found)} found: {', '.join(parts)} ({tried}, {seconds:.1f} s)"


def run_scan(args: argparse.Namespace) -> int:
    if args.parity != "E":
        raise CommandError("PROFIBUS characters are always 8E1: --parity E", Exit.BAD_INPUT)
    if args.baudrates is not None:
        raise CommandError("--baudrates is for FC and USS lines", Exit.BAD_INPUT)
    if args.retries > MAX_DP_RETRIES:
        raise CommandError(f"--retries: at most {MAX_DP_RETRIES} over PROFIBUS", Exit.BAD_INPUT)
    for option in ("access", "axis"):
        if getattr(args, option, None) is not None:
            raise CommandError(
                f"--{option}: the scan parametrises no slave (data record 47 needs one in data"
                " exchange): use it with read, write or describe",
                Exit.BAD_INPUT,
            )
    addresses = parse_addresses(args.addresses, 0, 125) if args.addresses else list(range(126))
    addresses = [a for a in addresses if a != args.master_address]
    args.baudrate = args.baudrate or DEFAULT_BAUDRATE
    progress = Progress(sys.stderr, enabled=not args.json and sys.stderr.isatty())
    started = time.monotonic()
    found: list[dict[str, Any]] = link.run(_scan(args, addresses, progress))
    return report(args.json, found, summary(found, len(addresses), time.monotonic() - started))
