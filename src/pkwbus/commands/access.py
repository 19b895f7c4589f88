"""`pkwbus read` and `pkwbus write`: one parameter of one drive.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad input or
a port that cannot be opened.
"""

from __future__ import annotations

import argparse
import asyncio
from typing import Any

from pkwbus import durations, link
from pkwbus.catalog.description import ParameterDescription
from pkwbus.commands import dp_access
from pkwbus.commands.answers import catalog_entry, drive_name, finish, report_value, show_read
from pkwbus.commands.common import (
    DEFAULT_CATALOG,
    PROFIBUS,
    CommandError,
    Exit,
    add_drive_options,
    add_line_options,
    build_line,
    build_target,
    duration_option,
)
from pkwbus.commands.dp import add_dp_options
from pkwbus.link import PortError
from pkwbus.master.outcomes import Outcome
from pkwbus.master.single_job import run_job
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.params import (
    ParameterRef,
    encode_text,
    parse_parameter,
    parse_type,
)
from pkwbus.protocol.telegram import Protocol

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


def _resolve(args: argparse.Namespace) -> tuple[DriveTarget, ParameterRef, ParameterDescription]:
    try:
        ref = parse_parameter(args.parameter)
        target = build_target(args)
        target.dialect.check_pnu(ref.pnu)
        vtype = parse_type(args.type) if args.type else None
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    known = _known(args, ref)
    try:
        ref = drive_name(ref, target, known)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    return target, ref, known.with_type(vtype)


def _known(args: argparse.Namespace, ref: ParameterRef) -> ParameterDescription:
    """What the catalog named on the command line says of ``ref`` (nothing with 'none')."""
    return catalog_entry(args.catalog or DEFAULT_CATALOG[Protocol(args.protocol)], ref.pnu)


async def _perform(args: argparse.Namespace, target: DriveTarget, req: pkw.PkwRequest) -> Outcome:
    line = build_line(args)
    try:
        await line.open()
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    try:
        deadline = asyncio.get_running_loop().time() + args.deadline
        return await run_job(line, target, req, retries=args.retries, deadline=deadline)
    finally:
        await line.close()


def run_read(args: argparse.Namespace) -> int:
    if args.protocol == PROFIBUS:
        return dp_access.run_read(args)
    target, ref, fmt = _resolve(args)
    try:
        req = pkw.read_parameter(target.dialect, ref.pnu, ref.index, text=fmt.is_text)
        target.telegram(req)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    return show_read(args, ref, fmt, link.run(_perform(args, target, req)))


def run_write(args: argparse.Namespace) -> int:
    if args.protocol == PROFIBUS:
        return dp_access.run_write(args)
    target, ref, fmt = _resolve(args)
    store = pkw.Store(args.store)
    try:
        if fmt.is_text:
            req = pkw.write_text(target.dialect, ref.pnu, encode_text(args.value), ref.index or 0)
            raw: int | None = None
        else:
            raw, width = fmt.encode(args.value, str(ref))
            req = pkw.write(target.dialect, ref.pnu, raw, width, index=ref.index, store=store)
        target.telegram(req)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    response = finish(link.run(_perform(args, target, req)))
    try:
        raw, value = fmt.value_of(response)
    except RemoteProtocolError:
        value = args.value
    report_value(args, ref, raw, value, fmt, f" written ({store.value})")
    return Exit.OK
