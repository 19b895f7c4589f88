"""What `pkwbus read`, `write` and `describe` share (FC, USS and PROFIBUS alike): the
drive's name for a parameter, and how a command ends: an outcome made an answer or an
exit, and a value printed.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for an outcome
that is not an answer, or an answer that cannot be read.
"""

from __future__ import annotations

import argparse

from pkwbus.catalog import CatalogError, load_catalog
from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.commands.common import CommandError, Exit, emit_json
from pkwbus.commands.failures import command_failure
from pkwbus.master.planning.outcomes import Answered, Outcome
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.values import ParameterRef, canonical

__all__ = ["catalog_entry", "drive_name", "finish", "report_value", "show_read"]


def catalog_entry(catalog: str, pnu: int) -> ParameterDescription:
    """What ``catalog`` says of ``pnu`` (nothing with 'none'); a catalog that does not load
    is a bad option (exit 2)."""
    if catalog == "none":
        return ParameterDescription()
    try:
        return ParameterDescription.from_spec(load_catalog(catalog).get(pnu))
    except CatalogError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None


def drive_name(
    ref: ParameterRef, dialect: Dialect, known: ParameterDescription | None
) -> ParameterRef:
    """The drive's one name for ``ref`` (3-41 on an FC drive, r/p refused there);
    elsewhere the catalog's r/p, else the one given on the command line."""
    prefix = known.prefix if known is not None and known.prefix else ref.prefix
    return canonical(ref, danfoss=dialect.danfoss_numbers, prefix=prefix)


def finish(outcome: Outcome) -> pkw.PkwResponse:
    failure = command_failure(outcome)
    if failure is not None:
        raise CommandError(failure.message, failure.code, kind=failure.kind, fault=failure.fault)
    assert isinstance(outcome, Answered)  # the one outcome without a failure
    return outcome.response


def report_value(
    args: argparse.Namespace,
    ref: ParameterRef,
    raw: int | None,
    value: Value,
    fmt: ParameterDescription,
    verb: str = "",
) -> None:
    if args.json:
        emit_json(
            {
                "parameter": ref.name,
                "pnu": ref.pnu,
                "index": ref.index or 0,
                "raw": raw,
                "value": value,
                "unit": fmt.unit,
            }
        )
        return
    unit = f" {fmt.unit}" if fmt.unit else ""
    rawtext = f" (raw {raw})" if raw is not None and raw != value else ""
    print(f"{ref} = {value}{unit}{rawtext}{verb}")


def show_read(
    args: argparse.Namespace, ref: ParameterRef, fmt: ParameterDescription, outcome: Outcome
) -> int:
    """The answer to a read, printed as ``read`` prints it (FC, USS and PROFIBUS alike)."""
    response = finish(outcome)
    try:
        raw, value = fmt.value_of(response)
    except RemoteProtocolError as exc:
        raise CommandError(f"unusable answer: {exc}", Exit.NO_ANSWER) from None
    report_value(args, ref, raw, value, fmt)
    return Exit.OK
