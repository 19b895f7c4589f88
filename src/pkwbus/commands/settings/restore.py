"""`pkwbus restore`: a backup document's settings written to one drive, directly on the
port (not through the service), as the service's ``POST .../restore`` does.

The backup (JSON or YAML, :class:`pkwbus.service.history.backup.Backup`) is read first;
a file that is not one is bad input, nothing sent. Then the drive's identity, what it
says of each setting (its description: type, scaling, limits, read-only; FC element
21) and its present value, decoded as `pkwbus read` decodes. The plan
(:func:`pkwbus.service.history.backup.plan_restore`) writes what differs, in the
backup's order, and skips with its reason what cannot be written; it is printed, and
with ``--dry-run`` nothing more happens. Otherwise each planned value is written as
`pkwbus write` writes it (EEPROM unless ``--store ram``) and read back, by the rules of
:mod:`pkwbus.service.history.restore` (the API's restore follows them too):

- a read-back with another value, or a write or read-back without an answer, stops
  the restore (the rest is reported not sent): exit 5 (mismatch) or 3 (no answer);
- a write the drive refuses (FC fault 17: "can only be changed when the motor is
  turned off") is reported with the drive's text, and the restore goes on: exit 1;
- a backup of another drive type (or dialect) is not restored without ``--force``:
  every setting is skipped, nothing is written, exit 2.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad input,
a port that cannot be opened, or a drive that does not answer before anything is
written.
"""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus import link
from pkwbus.catalog import available_catalogs
from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.commands.answers import catalog_entry, drive_name
from pkwbus.commands.common import CommandError, add_drive_options, add_line_options
from pkwbus.commands.drive_access import DriveAccess, drive_access
from pkwbus.commands.failures import command_failure
from pkwbus.commands.profibus.context import add_dp_options
from pkwbus.commands.settings.files import load_backup
from pkwbus.commands.settings.reads import (
    add_deadline_option,
    describe_settings,
    formats,
    identify,
    run_all,
)
from pkwbus.commands.settings.report import Restored, exit_code, report
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.values import ParameterRef, parse_parameter
from pkwbus.service.history.backup import (
    Backup,
    Planned,
    Present,
    Skipped,
    drive_type,
    plan_restore,
)
from pkwbus.service.history.restore import carry_out

__all__ = ["add_parsers", "run_restore"]

Key = tuple[str, int]
Target = tuple[ParameterRef, ParameterDescription]


def add_parsers(sub: Any) -> None:
    restore = sub.add_parser("restore", help="write a backup's settings to a drive")
    restore.add_argument("file", metavar="FILE", help="backup file (JSON or YAML); - stdin")
    add_line_options(restore)
    add_drive_options(restore)
    add_dp_options(restore)
    restore.add_argument("--catalog", default=None, help="catalog (default: the backup's)")
    restore.add_argument("--dry-run", action="store_true", help="print the plan, write nothing")
    restore.add_argument("--store", choices=[s.value for s in pkw.Store], default="eeprom")
    restore.add_argument("--force", action="store_true", help="restore another drive type's backup")
    add_deadline_option(restore)
    restore.set_defaults(func=run_restore)


def run_restore(args: argparse.Namespace) -> int:
    backup = load_backup(args.file)
    access = drive_access(args)
    catalog = _catalog(args, backup, access)
    identity, _ = identify(access, setup=False)
    other = _other(backup, access, identity)
    if other is not None and not args.force:
        skipped = [Skipped(s.parameter, s.index, other) for s in backup.settings]
        done = Restored(backup, identity, [], skipped, args.dry_run, other=other)
        report(args, done)
        return exit_code(done)
    present, targets = _present(access, backup, catalog)
    plan, skipped = plan_restore(backup, present, target_identity=identity, force=args.force)
    done = Restored(backup, identity, plan, skipped, args.dry_run)
    store = pkw.Store(args.store)

    async def write(step: Planned) -> dict[str, Any]:
        ref, fmt = targets[(step.parameter, step.index)]
        if args.dry_run:  # each write checked as it would go out, none sent
            made = _request(access, ref, fmt, step.new, store)
            return {"outcome": "dry_run"} if not isinstance(made, str) else _invalid(made)
        return await _write(access, ref, fmt, step.new, store)

    done.results = link.run(carry_out(plan, write))
    report(args, done)
    return exit_code(done)


def _catalog(args: argparse.Namespace, backup: Backup, access: DriveAccess) -> str:
    """--catalog, else the backup's where pkwbus has it, else the bus's; one that does not
    load is a bad option (exit 2), before anything is sent."""
    if args.catalog:
        catalog_entry(args.catalog, 0)  # it loads, or exit 2
        return str(args.catalog)
    if backup.catalog in available_catalogs():
        return backup.catalog
    return access.catalog


def _other(backup: Backup, access: DriveAccess, identity: str | None) -> str | None:
    """Why the backup is not this drive's: another dialect or drive type; None if it is."""
    dialect = access.dialect.name
    if backup.dialect and backup.dialect != dialect:
        return f"the backup is of another dialect ({backup.dialect}, this drive speaks {dialect})"
    theirs, ours = drive_type(backup.identity), drive_type(identity)
    if theirs is not None and ours is not None and theirs != ours:
        return f"the backup is of another drive type ({theirs}, this drive is {ours})"
    return None


def _present(
    access: DriveAccess, backup: Backup, catalog: str
) -> tuple[dict[Key, Present], dict[Key, Target]]:
    """What the drive says now of each setting of ``backup`` that has a number to
    restore, and how each is named and described on it."""
    d = access.dialect
    present: dict[Key, Present] = {}
    named: dict[Key, tuple[ParameterRef, ParameterDescription]] = {}
    for s in backup.settings:
        key = (s.parameter, s.index)
        if s.value is None or isinstance(s.value, str):
            continue  # the plan skips it, saying why
        try:
            ref = parse_parameter(s.parameter)
            d.check_pnu(ref.pnu)
            known = catalog_entry(catalog, ref.pnu)
            ref = drive_name(ref, d, known)
        except LocalProtocolError as exc:
            present[key] = Present(None, ParameterDescription(), refused=str(exc))
            continue
        array = bool(s.index or ref.index is not None or known.array)
        named[key] = (ParameterRef(ref.pnu, s.index if array else None, ref.name), known)
    said = describe_settings(access, (ref.pnu for ref, _ in named.values()), limits=True)
    reads = [pkw.read(d, ref.pnu, ref.index) for ref, _ in named.values()]
    targets: dict[Key, Target] = {}
    for (key, (ref, known)), outcome in zip(named.items(), run_all(access, reads), strict=True):
        described = said.get(ref.pnu)
        fmt = formats(known, described)
        if isinstance(outcome, Rejected):
            present[key] = Present(None, fmt, refused=outcome.text)
            continue
        assert isinstance(outcome, Answered)  # run_all stops at anything else
        response = outcome.response
        if fmt.vtype is None and isinstance(response, pkw.ValueResponse):
            fmt = fmt.with_type(response.vtype)  # the type the drive names in its answer
        try:
            value: Value | None = fmt.value_of(response)[1]
        except RemoteProtocolError:
            value = None
        said_read_only = described is not None and bool(described.drive.read_only)
        read_only = fmt.prefix == "r" or said_read_only
        characteristics = None if described is None else described.characteristics
        present[key] = Present(value, fmt, None, characteristics, read_only)
        targets[key] = (ref, fmt)
    return present, targets


async def _write(
    access: DriveAccess, ref: ParameterRef, fmt: ParameterDescription, value: Value,
    store: pkw.Store,
) -> dict[str, Any]:  # fmt: skip
    """One write as `pkwbus write` sends it, then its read-back: the outcome (ok,
    rejected, mismatch, unverified, timeout, line_error, invalid) and what it says."""
    d = access.dialect
    made = _request(access, ref, fmt, value, store)
    if isinstance(made, str):
        return _invalid(made)
    raw, request = made
    back = pkw.read(d, ref.pnu, ref.index)
    try:
        written, answer = await access.run([request, back], fmt.vtype)
    except CommandError as exc:  # the port cannot be opened any more
        return {"outcome": "line_error", "detail": str(exc)}
    failure = command_failure(written)
    if failure is not None:
        result: dict[str, Any] = {"outcome": failure.kind, "detail": failure.message}
        if failure.fault is not None:
            result["fault"] = failure.fault
        return result
    if not isinstance(answer, Answered) or not isinstance(answer.response, pkw.ValueResponse):
        why = answer.text if isinstance(answer, Rejected) else "no answer"
        return {"outcome": "unverified", "detail": f"the read-back failed: {why}"}
    if answer.response.raw != raw:
        try:
            held: Value | str = fmt.value_of(answer.response)[1]
        except RemoteProtocolError:
            held = "?"
        unit = f" {fmt.unit}" if fmt.unit else ""
        detail = (
            f"read back {held}{unit} (raw {answer.response.raw}), not {value}{unit} (raw {raw})"
        )
        return {"outcome": "mismatch", "detail": detail}
    return {"outcome": "ok", "raw": raw}


def _request(
    access: DriveAccess, ref: ParameterRef, fmt: ParameterDescription, value: Value,
    store: pkw.Store,
) -> tuple[int, pkw.PkwRequest] | str:  # fmt: skip
    """The raw value and the write request of ``value``, as `pkwbus write` makes them; why
    not, where it cannot go out (a value its type cannot hold exactly, say)."""
    try:
        raw, width = fmt.encode(value, str(ref))
        request = pkw.write(access.dialect, ref.pnu, raw, width, index=ref.index, store=store)
        access.check(request)
    except LocalProtocolError as exc:
        return str(exc)
    return raw, request


def _invalid(why: str) -> dict[str, Any]:
    return {"outcome": "invalid", "detail": f"not sent: {why}"}
