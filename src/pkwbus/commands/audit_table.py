"""`pkwbus audit` for people: one aligned row per write attempt.

The time is local with its offset (ISO 8601, ``2025-03-01T10:00:07+01:00``);
a change reads ``old -> new`` with the parameter's unit from the drive's
catalog and the configuration. Rows of refused requests (one per client
address and minute) show their count instead of a change.
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable, Sequence
from typing import Any

from pkwbus.catalog import CatalogError
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.values import parse_parameter
from pkwbus.service.audit.log import AuditEntry
from pkwbus.service.config import Config, ConfigError

__all__ = ["HEADER", "UnitOf", "row", "stamp", "table", "units_from", "value_text"]

HEADER = ("TIME", "DRIVE", "PARAMETER", "CHANGE", "STORE", "OUTCOME", "CLIENT", "DETAIL")
UnitOf = Callable[[str, str], str]


def units_from(config: Config) -> UnitOf:
    """The unit of ``(drive, parameter)`` as the configuration's catalogs give it, else ""."""
    drives = {d.name: d for line in config.lines for d in line.drives}

    def unit(drive: str, parameter: str) -> str:
        found = drives.get(drive)
        if found is None:
            return ""
        try:
            spec = found.spec(parse_parameter(parameter))
        except (LocalProtocolError, CatalogError, ConfigError, LookupError, ValueError):
            return ""
        return spec.unit if spec is not None else ""

    return unit


def stamp(seconds: float, tz: datetime.tzinfo | None = None) -> str:
    """``seconds`` since the epoch as local (or ``tz``) ISO 8601 time with its offset."""
    moment = datetime.datetime.fromtimestamp(seconds, tz=datetime.UTC)
    return moment.astimezone(tz).isoformat(timespec="seconds")


def value_text(value: Any, unit: str) -> str:
    if value is None:
        return "?"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        value = int(value)
    return f"{value} {unit}" if unit else str(value)


def row(entry: AuditEntry, unit_of: UnitOf, tz: datetime.tzinfo | None = None) -> list[str]:
    when = stamp(entry.time, tz)
    if entry.count is not None:  # the refusals from one address in one minute
        return [
            when,
            "-",
            "-",
            f"{entry.count} request(s)",
            "-",
            "refused",
            entry.client,
            entry.detail or "",
        ]
    parameter = entry.parameter + (f"[{entry.index}]" if entry.index else "")
    unit = unit_of(entry.drive, entry.parameter) if entry.parameter else ""
    change = f"{value_text(entry.old_value, unit)} -> {value_text(entry.new_value, unit)}"
    outcome = entry.outcome + (f" fault {entry.fault}" if entry.fault is not None else "")
    return [
        when,
        entry.drive or "-",
        parameter or "-",
        change,
        entry.store or "-",
        outcome,
        entry.client,
        entry.detail or "",
    ]


def table(
    entries: Sequence[AuditEntry], unit_of: UnitOf, tz: datetime.tzinfo | None = None
) -> list[str]:
    """The header and one line per entry, columns aligned (the last one left free)."""
    rows = [list(HEADER)] + [row(e, unit_of, tz) for e in entries]
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER) - 1)]
    return [
        "  ".join([*(cell.ljust(w) for cell, w in zip(r, widths, strict=False)), r[-1]]).rstrip()
        for r in rows
    ]
