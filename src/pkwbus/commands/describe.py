"""`pkwbus describe`: a parameter's type, conversion index, name and limits, from the drive.

Drives answer description elements (AK 4): 1 data type (PROFIdrive: the
identifier), 2 number of array elements, 4 conversion and unit index, 6 name,
7 low limit, 8 high limit; in the Danfoss FC form over the FC protocol, in the
PROFIdrive form over USS and PROFIBUS (:mod:`pkwbus.commands.descriptions`).
The same requests on every bus (:mod:`pkwbus.commands.drive_access`).

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad input, a
port that cannot be opened or an answer that is a fault.
"""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus import link
from pkwbus.commands.common import CommandError, Exit, add_drive_options, add_line_options
from pkwbus.commands.descriptions import ELEMENTS, report
from pkwbus.commands.drive_access import checked, drive_access, resolve
from pkwbus.commands.failures import command_failure
from pkwbus.commands.profibus.context import add_dp_options
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import Command

__all__ = ["add_parsers", "run_describe"]


def add_parsers(sub: Any) -> None:
    describe = sub.add_parser("describe", help="read a parameter's description from the drive")
    add_line_options(describe)
    add_drive_options(describe)
    add_dp_options(describe)
    describe.add_argument("parameter", help="16-13, 1613, r0021")
    describe.set_defaults(func=run_describe)


def run_describe(args: argparse.Namespace) -> int:
    access = drive_access(args)
    if not access.dialect.has(Command.READ_DESCRIPTION):
        raise CommandError(
            f"the {access.dialect.name} dialect has no description request (AK 4)", Exit.BAD_INPUT
        )
    ref, _ = resolve(args, access, typed=False)
    requests = checked(access, [pkw.read_description(access.dialect, ref.pnu, e) for e in ELEMENTS])
    outcomes = link.run(access.run(requests, None))
    found: dict[int, pkw.DescriptionResponse | None] = {}
    for element, outcome in zip(ELEMENTS, outcomes, strict=True):
        if isinstance(outcome, Answered) and isinstance(outcome.response, pkw.DescriptionResponse):
            found[element] = outcome.response
        elif isinstance(outcome, Answered | Rejected):
            found[element] = None  # this element is not available
        else:
            failure = command_failure(outcome)
            assert failure is not None  # only an answer has none
            raise CommandError(failure.message, failure.code)
    return report(args, ref, found, access.dialect)
