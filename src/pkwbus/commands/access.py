"""`pkwbus read` and `pkwbus write`: one parameter of one drive, the same on every bus
(:mod:`pkwbus.commands.drive_access`).

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad input or
a port that cannot be opened.
"""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus import link
from pkwbus.commands.answers import finish, report_value, show_read
from pkwbus.commands.common import (
    CommandError,
    Exit,
    add_drive_options,
    add_line_options,
    duration_option,
)
from pkwbus.commands.drive_access import DriveAccess, checked, drive_access, resolve
from pkwbus.commands.profibus.context import add_dp_options
from pkwbus.master.planning.outcomes import Answered
from pkwbus.notation import durations
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.values import ParameterRef, encode_text
from pkwbus.protocol.values.types import ValueType

__all__ = [
    "add_parsers",
    "run_read",
    "run_write",
]


def add_parsers(sub: Any) -> None:
    read = sub.add_parser("read", help="read one parameter")
    _common(read)
    read.set_defaults(func=run_read)
    write = sub.add_parser("write", help="write one parameter")
    _common(write)
    write.add_argument("value", help="engineering value (scaled by the catalog) or text")
    write.add_argument("--store", choices=[s.value for s in pkw.Store], default="ram")
    write.set_defaults(func=run_write)


def _common(parser: argparse.ArgumentParser) -> None:
    add_line_options(parser)
    add_drive_options(parser)
    add_dp_options(parser)
    parser.add_argument("parameter", help="16-13 (FC), r0021, p1082[2] (USS), or the plain number")
    parser.add_argument("--type", default=None, help="u16 i16 u32 i32 f32 text")
    parser.add_argument("--catalog", default=None, help="catalog name, or 'none'")
    parser.add_argument(
        "--deadline",
        type=duration_option(durations.JOB_DEADLINE),
        default=2.0,
        help=f"for the whole job, retries included (default 2s; {durations.JOB_DEADLINE})",
    )


def run_read(args: argparse.Namespace) -> int:
    access = drive_access(args)
    ref, fmt = resolve(args, access)
    text = fmt.is_text and access.texts
    (req,) = checked(access, [pkw.read_parameter(access.dialect, ref.pnu, ref.index, text=text)])
    (outcome,) = link.run(access.run([req], fmt.vtype))
    return show_read(args, ref, fmt, outcome)


def run_write(args: argparse.Namespace) -> int:
    access = drive_access(args)
    ref, fmt = resolve(args, access)
    if fmt.vtype is None and access.typed_answers:
        fmt = fmt.with_type(_stated_type(access, ref))
    store = pkw.Store(args.store)
    d = access.dialect
    try:
        if fmt.is_text:
            req = pkw.write_text(d, ref.pnu, encode_text(args.value), ref.index or 0)
            raw: int | None = None
        else:
            raw, width = fmt.encode(args.value, str(ref))
            req = pkw.write(d, ref.pnu, raw, width, index=ref.index, store=store)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    (outcome,) = link.run(access.run(checked(access, [req]), fmt.vtype))
    response = finish(outcome)
    try:
        raw, value = fmt.value_of(response)
    except RemoteProtocolError:
        value = args.value
    report_value(args, ref, raw, value, fmt, f" written ({store.value})")
    return Exit.OK


def _stated_type(access: DriveAccess, ref: ParameterRef) -> ValueType | None:
    """The type the drive names for ``ref`` in its answer to a read (a typed format of
    data record 47); None where its answer names none (or no answer came: the write is
    then refused for want of a type, unsent)."""
    (req,) = checked(access, [pkw.read_parameter(access.dialect, ref.pnu, ref.index, text=False)])
    (outcome,) = link.run(access.run([req], None))
    response = outcome.response if isinstance(outcome, Answered) else None
    return response.vtype if isinstance(response, pkw.ValueResponse) else None
