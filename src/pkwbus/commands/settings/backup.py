"""`pkwbus backup`: one drive's settings as a backup document, read directly on the port
(not through the service), the same document the service's API gives
(:class:`pkwbus.service.history.backup.Backup`).

The drive's identity, its Danfoss active set-up (0-10), the time, and every setting of
its catalog (each element of an array) with its value, unit and raw number, in the
catalog's order (:mod:`pkwbus.commands.settings.reads`). A text is not backed up, as
the service's sweep does not read one; a setting the drive refuses to read is left out
and named on stderr. JSON, or YAML for a FILE ending in .yaml or .yml; ``-o -`` (or
no ``-o``): stdout. The file is written only once every read is done.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad input,
a port that cannot be opened, a drive that does not answer, or a file that cannot be
written.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any

from pkwbus.commands.common import CommandError, Exit, add_drive_options, add_line_options
from pkwbus.commands.drive_access import drive_access
from pkwbus.commands.profibus.context import add_dp_options
from pkwbus.commands.settings.files import check_output, write_document
from pkwbus.commands.settings.reads import (
    add_deadline_option,
    catalog_settings,
    describe_settings,
    formats,
    identify,
    run_all,
)
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.service.history.backup import Backup, BackupSetting

__all__ = ["add_parsers", "run_backup"]


def add_parsers(sub: Any) -> None:
    backup = sub.add_parser("backup", help="save a drive's settings to a file")
    add_line_options(backup)
    add_drive_options(backup)
    add_dp_options(backup)
    backup.add_argument("--catalog", default=None, help="catalog whose settings are read")
    backup.add_argument("--name", type=_drive_name, default=None, help="drive name (drive-N)")
    backup.add_argument(
        "-o", "--output", default="-", metavar="FILE", help="JSON, or YAML for .yaml/.yml; - stdout"
    )
    add_deadline_option(backup)
    backup.set_defaults(func=run_backup)


def _drive_name(text: str) -> str:
    if not 1 <= len(text) <= 64:
        raise argparse.ArgumentTypeError("a drive name has 1-64 characters")
    return text


def run_backup(args: argparse.Namespace) -> int:
    check_output(args.output)
    access = drive_access(args)
    catalog = args.catalog or access.catalog
    settings = [s for s in catalog_settings(catalog, access.dialect) if not s.known.is_text]
    if not settings:
        raise CommandError(
            f"catalog {catalog!r} names no settings to back up: give --catalog", Exit.BAD_INPUT
        )
    identity, setup = identify(access, setup=True)
    said = describe_settings(access, (s.ref.pnu for s in settings), limits=False)
    d = access.dialect
    outcomes = run_all(access, [pkw.read(d, s.ref.pnu, s.ref.index) for s in settings])
    seen = _now()
    rows: list[BackupSetting] = []
    for s, outcome in zip(settings, outcomes, strict=True):
        fmt = formats(s.known, said.get(s.ref.pnu))
        if isinstance(outcome, Rejected):
            print(f"pkwbus: {s.ref} is not backed up: the drive refuses it: {outcome.text}",
                  file=sys.stderr)  # fmt: skip
            continue
        assert isinstance(outcome, Answered)  # run_all stops at anything else
        try:
            raw, value = fmt.value_of(outcome.response)
        except RemoteProtocolError as exc:
            raise CommandError(f"{s.ref}: unusable answer: {exc}", Exit.NO_ANSWER) from None
        if fmt.is_text or raw is None:
            print(f"pkwbus: {s.ref} is not backed up: a text", file=sys.stderr)
            continue
        if isinstance(value, float) and not math.isfinite(value):
            print(f"pkwbus: {s.ref} is not backed up: {value} is no number", file=sys.stderr)
            continue
        rows.append(BackupSetting(
            parameter=s.ref.name, index=s.ref.index or 0, name=fmt.name, value=value,
            unit=fmt.unit, raw=raw, seen=seen,
        ))  # fmt: skip
    document = Backup(
        drive=args.name or f"drive-{args.address}",
        line="",
        dialect=d.name,
        catalog=None if catalog == "none" else catalog,
        identity=identity,
        setup=setup,
        time=_now(),
        settings=rows,
    )
    write_document(args.output, document.model_dump())
    if args.output != "-":
        print(f"{len(rows)} setting(s) of {document.drive} saved to {args.output}",
              file=sys.stderr)  # fmt: skip
    return Exit.OK


def _now() -> str:
    """Now as the service's API writes times: ISO 8601 in UTC, to the millisecond."""
    from pkwbus.service.history.times import iso_time

    return iso_time(time.time())
