"""`pkwbus check-config --probe`: each configured drive asked once, with the line's settings.

Each FC or USS line's port is opened briefly and every drive gets one short
telegram (the one a down drive is probed with), retried as the line says. A
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
from pkwbus.master.planning.answers import Failure, Reply
from pkwbus.master.sessions.probe import NO_ANSWER, ask_description, ask_pkw_length
from pkwbus.master.target import DriveTarget
from pkwbus.master.wires.serial.line import Line
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.pkw.length import AUTO, shown
from pkwbus.protocol.serial.telegram import Protocol
from pkwbus.service import config as cfg
from pkwbus.service.assembly.build import (
    describe_targets,
    description_form,
    line_for,
    target_for,
)
from pkwbus.service.assembly.parameter_table import parameter_table

__all__ = ["probe", "run_probe"]


def probe(config: cfg.Config) -> tuple[list[str], bool]:
    """The report's lines, and whether every probed drive answered."""
    return link.run(_probe(config))


async def _probe(config: cfg.Config) -> tuple[list[str], bool]:
    report: list[str] = []
    every = True
    for line in config.lines:
        if line.sim is not None:
            report.append(f"line {line.name}: simulated ({line.port}), not probed")
            continue
        if line.protocol is Protocol.PROFIBUS:
            report.append(
                f"line {line.name}: PROFIBUS, not probed here: "
                f"pkwbus scan --protocol profibus --port {line.port} lists its stations"
            )
            continue
        answered, lines = await _probe_line(line)
        report += lines
        every = every and answered
    return report, every


async def _probe_line(line: cfg.Line) -> tuple[bool, list[str]]:
    bus = line_for(line, line.port)
    try:
        await bus.open()
    except PortError as exc:
        return False, [f"line {line.name}: cannot open {line.port}: {exc}"]
    out = [f"line {line.name}: {line.port} open, {line.baudrate} baud {line.parity}"]
    every = True
    try:
        for drive in line.drives:
            target = target_for(line, drive)
            result = None
            for _ in range(line.retries + 1):
                result = await bus.exchange(target.adr, target.probe())
                if isinstance(result, Reply) or (
                    isinstance(result, Failure) and result.kind.value == "port"
                ):
                    break
            if isinstance(result, Reply):
                told = await _pkw_length(bus, line, target)
                out.append(f"  {drive.name} (address {drive.address}): answers{told}")
                out += await _descriptions(bus, line, drive, target)
            else:
                every = False
                why = result.detail if isinstance(result, Failure) else "no answer"
                out.append(f"  {drive.name} (address {drive.address}): NO ANSWER ({why})")
        if bus.echo_heard:
            out.append(
                f"  the adapter on {line.port} echoes our requests: set echo: true for this line"
            )
    finally:
        await bus.close()
    return every, out


async def _pkw_length(bus: Line, line: cfg.Line, target: DriveTarget) -> str:
    """A USS drive's PKW length as its answer shows it, against the configured one."""
    if line.protocol is not Protocol.USS or not target.has_pkw:
        return ""
    deadline = asyncio.get_running_loop().time() + line.timeout * (line.retries + 1) + 0.5
    words = await ask_pkw_length(bus, target, retries=line.retries, deadline=deadline)
    if words == NO_ANSWER:
        return ", PKW length not told (no answer to a word read)"
    seen = "4 or 127" if words == "?" else shown(words)
    configured = target.pkw_setting
    if configured == AUTO or words == "?" or words == configured:
        return f", PKW length {seen} (pkw_words: {shown(configured)})"
    return f", PKW length {seen}, but pkw_words is {shown(configured)}: CONFLICT, no write goes out"


async def _descriptions(
    bus: Line, line: cfg.Line, drive: cfg.Drive, target: DriveTarget
) -> list[str]:
    """Each polled and writable parameter as the drive describes it, against its catalog."""
    if description_form(line, drive) is None:
        return []
    out = []
    table = parameter_table(drive)
    for wanted in describe_targets(target, drive, table):
        said = await ask_description(
            bus, target, wanted.pnu, retries=line.retries, timeout=line.timeout * 3 + 0.5
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
    if not every:
        raise CommandError("some drives did not answer (see above)", Exit.NO_ANSWER)
    return Exit.OK
