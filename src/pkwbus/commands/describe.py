"""`pkwbus describe`: a parameter's type, conversion index, name and limits, from the drive.

FC 300-style drives (and PROFIdrive ones) answer description elements (AK 4):
1 data type, 2 number of array elements, 4 conversion index (high byte) and
unit index (low byte), 6 name, 7 low limit, 8 high limit.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad input, a
port that cannot be opened or an answer that is a fault.
"""

from __future__ import annotations

import argparse
import asyncio
from typing import Any

from pkwbus import link
from pkwbus.commands import dp_access
from pkwbus.commands.answers import drive_name
from pkwbus.commands.common import (
    PROFIBUS,
    CommandError,
    Exit,
    add_drive_options,
    add_line_options,
    build_line,
    build_target,
)
from pkwbus.commands.descriptions import ELEMENTS, report
from pkwbus.commands.dp import add_dp_options
from pkwbus.commands.failures import command_failure
from pkwbus.link import PortError
from pkwbus.master.line import Line
from pkwbus.master.outcomes import Answered, Rejected
from pkwbus.master.single_job import run_job
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.dialects import Command
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.params import (
    parse_parameter,
)

__all__ = ["add_parsers", "run_describe"]


def add_parsers(sub: Any) -> None:
    describe = sub.add_parser("describe", help="read a parameter's description from the drive")
    add_line_options(describe)
    add_drive_options(describe)
    add_dp_options(describe)
    describe.add_argument("parameter", help="16-13, 1613, r0021")
    describe.set_defaults(func=run_describe)


async def _elements(
    args: argparse.Namespace, target: DriveTarget, pnu: int
) -> dict[int, pkw.DescriptionResponse | None]:
    line = build_line(args)
    try:
        await line.open()
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    found: dict[int, pkw.DescriptionResponse | None] = {}
    try:
        for element in ELEMENTS:
            found[element] = await _element(line, args, target, pnu, element)
    finally:
        await line.close()
    return found


async def _element(
    line: Line, args: argparse.Namespace, target: DriveTarget, pnu: int, element: int
) -> pkw.DescriptionResponse | None:
    request = pkw.read_description(target.dialect, pnu, element)
    deadline = asyncio.get_running_loop().time() + 2.0
    outcome = await run_job(line, target, request, retries=args.retries, deadline=deadline)
    if isinstance(outcome, Answered):
        response = outcome.response
        return response if isinstance(response, pkw.DescriptionResponse) else None
    if isinstance(outcome, Rejected):
        return None  # this element is not available
    failure = command_failure(outcome)
    assert failure is not None  # only an answer has none
    raise CommandError(failure.message, failure.code)


def run_describe(args: argparse.Namespace) -> int:
    if args.protocol == PROFIBUS:
        return dp_access.run_describe(args)
    try:
        ref = parse_parameter(args.parameter)
        target = build_target(args)
        if not target.dialect.has(Command.READ_DESCRIPTION):
            raise LocalProtocolError(
                f"the {target.dialect.name} dialect has no description request (AK 4)"
            )
        target.dialect.check_pnu(ref.pnu)
        ref = drive_name(ref, target, None)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    found = link.run(_elements(args, target, ref.pnu))
    return report(args, ref, found)
