"""`pkwbus scan --protocol profibus`: the live list of a DP line.

After listening for other masters (none may be active), pkwbus asks every
address 0-125 but its own for its FDL status (EN 50170 vol. 2 part 4, "FDL
status"): the answer says whether a station is there and whether it is a
slave or a master. Each slave is then asked its diagnosis (Slave_Diag):
ident number, state, and the master that owns it. Nothing is parametrised.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad options,
a port that cannot be opened or a line another master runs.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from pkwbus import link
from pkwbus.commands.common import CommandError, Exit
from pkwbus.commands.profibus.context import DEFAULT_BAUDRATE, MAX_DP_RETRIES, dp_line
from pkwbus.commands.scanning import Progress, parse_addresses, report
from pkwbus.link import PortError
from pkwbus.master.wires.profibus.line import DpLine, ForeignMaster
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import Answer
from pkwbus.protocol.profibus.fdl import DataFrame, StationType

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


async def _ask(line: DpLine, frame: DataFrame, tries: int) -> DataFrame | None:
    """The station's data answer to ``frame`` (repeated up to ``tries`` times), or None."""
    for _ in range(tries):
        answer: Answer = await line.exchange(frame)
        if isinstance(answer, DataFrame) and answer.sa == frame.da and answer.da == line.master:
            return answer
    return None


async def _station(line: DpLine, address: int, tries: int) -> dict[str, Any] | None:
    status = DataFrame(address, line.master, fdl.request_fc(fdl.Function.FDL_STATUS))
    answer = await _ask(line, status, tries)
    if answer is None or answer.control.is_request:
        return None
    kind = answer.control.station_type or StationType.SLAVE
    entry: dict[str, Any] = {"address": address, "station_type": STATION_TYPES[kind]}
    if kind is not StationType.SLAVE:
        return entry
    entry.update(ident=None, state=None, master=None, flags=[])
    request = dps.request(dps.Service.SLAVE_DIAG, address, line.master, fcb=True, fcv=False)
    diag_answer = await _ask(line, request, tries)
    if diag_answer is None:
        return entry
    try:
        diag = dps.decode_diagnosis(diag_answer.data)
    except RemoteProtocolError:
        return entry
    entry.update(
        ident=diag.ident, state=slave_state(diag), master=diag.master, flags=sorted(diag.flags)
    )
    return entry


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
    line = dp_line(args)
    try:
        await line.open()
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    found: list[dict[str, Any]] = []
    try:
        progress.show(f"listening for other masters ({line.token_lost_time():.2f} s)")
        await line.listen()
        for i, address in enumerate(addresses, 1):
            progress.show(f"address {address} ({i}/{len(addresses)}), {len(found)} found")
            entry = await _station(line, address, args.retries + 1)
            if entry is None:
                continue
            found.append(entry)
            if not args.json:
                progress.clear()
                print(_describe(entry), flush=True)
    except ForeignMaster as exc:
        raise CommandError(str(exc), Exit.NO_ANSWER, kind="line_error") from None
    except PortError as exc:
        raise CommandError(str(exc), Exit.NO_ANSWER) from None
    finally:
        progress.clear()
        await line.close()
    return found


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
