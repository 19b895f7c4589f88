"""`pkwbus check-config --probe`: each configured drive asked once, with the line's settings.

Each FC or USS line's port is opened briefly by its line runner and every
drive gets a probe job: one short telegram (the one a down drive is probed
with), repeated as the line's retries say. A
drive that answers is listed (a USS drive with the PKW length its answer to a
word read shows, against the configured one), and with ``describe: auto``
each of its polled and writable parameters as the drive describes it (AK 4),
against its catalog entry; one that does not, with what came back instead.
An adapter that echoes the requests while the line's ``echo`` is off is
named. Simulated (``sim://``) lines are not probed, nor
are PROFIBUS lines: ``pkwbus scan --protocol profibus`` shows their live list.

Raises :class:`~pkwbus.commands.common.CommandError` (exit 3) when a drive does not
answer.
"""

from __future__ import annotations

import asyncio

from pkwbus import link
from pkwbus.catalog.precedence import disagreements
from pkwbus.commands.common import CommandError, Exit
from pkwbus.link import PortError
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.outcomes import Heard, LineFailed, TimedOut
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.sessions.probe import NO_ANSWER, ask_description, ask_pkw_length
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.pkw.length import AUTO, shown
from pkwbus.service import config as cfg
from pkwbus.service.config.resolved import (
    describe_targets,
    description_form,
    parameter_table,
    port_for,
    target_for,
)

__all__ = ["probe", "run_probe"]


def probe(config: cfg.Config) -> tuple[list[str], bool | None]:
    """The report's lines, and whether every probed drive answered (None: a line's port
    could not be opened)."""
    return link.run(_probe(config))


async def _probe(config: cfg.Config) -> tuple[list[str], bool | None]:
    """The report, and whether every probed drive answered (None: a line's port could not
    be opened)."""
    report: list[str] = []
    every: bool | None = True
    for line in config.lines:
        if line.sim is not None:
            report.append(f"line {line.name}: simulated ({line.port}), not probed")
            continue
        if line.protocol is Bus.PROFIBUS:
            report.append(
                f"line {line.name}: PROFIBUS, not probed here: "
                f"pkwbus scan --protocol profibus --port {line.port} lists its stations"
            )
            continue
        answered, lines = await _probe_line(line)
        report += lines
        if every is not None:
            every = None if answered is None else every and answered
    return report, every


async def _probe_line(line: cfg.Line) -> tuple[bool | None, list[str]]:
    bus = port_for(line, line.port)
    targets = {drive.name: target_for(line, drive) for drive in line.drives}
    specs = [DriveSpec(name, carrier_for(target)) for name, target in targets.items()]
    session = LineSession(bus, ExchangeWire(bus.timeout), specs, retries=line.retries)
    try:
        await session.open()
    except PortError as exc:
        said = str(exc)  # most name the port already: "cannot open /dev/ttyUSB0: ..."
        return None, [f"line {line.name}: {said if line.port in said else f'{line.port}: {said}'}"]
    out = [f"line {line.name}: {line.port} open, {line.baudrate} baud {line.parity}"]
    every = True
    loop = asyncio.get_running_loop()
    try:
        for drive in line.drives:
            target = targets[drive.name]
            deadline = loop.time() + _asking_time(line)
            outcome = (await session.probe(drive.name, deadline)).outcome
            if isinstance(outcome, Heard):
                told = await _pkw_length(session, line, drive.name, target)
                out.append(f"  {drive.name} (address {drive.address}): answers{told}")
                out += await _descriptions(session, line, drive, target)
            else:
                every = False
                why = outcome.reason if isinstance(outcome, TimedOut | LineFailed) else outcome
                out.append(f"  {drive.name} (address {drive.address}): NO ANSWER ({why})")
        if bus.echo_heard:
            out.append(
                f"  the adapter on {line.port} echoes our requests: set echo: true for this line"
            )
    finally:
        await session.close()
    return every, out


def _asking_time(line: cfg.Line) -> float:
    """Enough for every try of one job on ``line``, and a margin."""
    return line.timeout * (line.retries + 1) + 0.5


async def _pkw_length(session: LineSession, line: cfg.Line, name: str, target: DriveTarget) -> str:
    """A USS drive's PKW length as its answer shows it, against the configured one."""
    if line.protocol is not Bus.USS or not target.has_pkw:
        return ""
    deadline = asyncio.get_running_loop().time() + _asking_time(line)
    words = await ask_pkw_length(session, name, target, deadline=deadline)
    if words == NO_ANSWER:
        return ", PKW length not told (no answer to a word read)"
    seen = "4 or 127" if words == "?" else shown(words)
    configured = target.pkw_setting
    if configured == AUTO or words == "?" or words == configured:
        return f", PKW length {seen} (pkw_words: {shown(configured)})"
    return f", PKW length {seen}, but pkw_words is {shown(configured)}: CONFLICT, no write goes out"


async def _descriptions(
    session: LineSession, line: cfg.Line, drive: cfg.Drive, target: DriveTarget
) -> list[str]:
    """Each polled and writable parameter as the drive describes it, against its catalog."""
    if description_form(line, drive) is None:
        return []
    out = []
    table = parameter_table(drive)
    for wanted in describe_targets(target, drive, table):
        said = await ask_description(
            session, drive.name, target, wanted.pnu, timeout=_asking_time(line)
        )
        name = f"    {wanted.parameter}:"
        if said == NO_ANSWER:
            out.append(f"{name} no answer to its description (the catalog is used)")
        elif said is None:
            out.append(f"{name} the drive has no description of it (the catalog is used)")
        elif wanted.catalog is None:
            out.append(f"{name} {_said(said)}; not in the catalog: the drive's is used")
        elif found := disagreements(said, wanted.catalog):
            differ = "; ".join(f"{d.field}: drive {d.drive}, catalog {d.catalog}" for d in found)
            out.append(f"{name} {_said(said)}; the CATALOG DIFFERS ({differ}): the drive's is used")
        else:
            out.append(f"{name} {_said(said)}; the catalog agrees")
    return out


def _said(said: DriveDescription) -> str:
    parts = [said.type_name or "no type"]
    if said.scaling is not None:
        parts.append(f"x{float(said.scaling.factor):g}")
    if said.unit:
        parts.append(said.unit)
    if said.name:
        parts.append(repr(said.name))
    return "the drive says " + ", ".join(parts)


def run_probe(config: cfg.Config) -> int:
    lines, every = probe(config)
    for text in lines:
        print(text)
    if every is None:
        raise CommandError("a line's port cannot be opened (see above)", Exit.PORT)
    if not every:
        raise CommandError("some drives did not answer (see above)", Exit.NO_ANSWER)
    return Exit.OK
