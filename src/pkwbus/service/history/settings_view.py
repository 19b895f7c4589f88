"""A drive's settings as the API shows them (``GET /api/v1/drives/{name}/settings``): its
last sweep, each setting with its baseline, whether it changed, and what the drive says of
its factory setting (:mod:`.settings`)."""

from __future__ import annotations

from typing import Any

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.protocol import pkw
from pkwbus.protocol.values import ParameterRef
from pkwbus.protocol.values.encoding import decode_value
from pkwbus.service.history.setting_reads import Swept
from pkwbus.service.history.settings_store import stored_value

__all__ = ["changed_count", "settings_view"]


def changed_count(s: Swept) -> int:
    """How many of the drive's swept settings differ from their baseline (those its view
    marks ``changed``)."""
    rows = s.rows
    return sum(
        1 for ref in s.refs
        if (row := rows.get((ref.pnu, ref.index or 0))) is not None
        and row.changed_seen is not None
    )  # fmt: skip


def settings_view(s: Swept) -> dict[str, Any]:
    """The last sweep of ``s``'s drive, as the API shows it (times in seconds since the
    epoch)."""
    parameters = []
    for ref in s.refs:
        row = s.rows.get((ref.pnu, ref.index or 0))
        fmt = s.format_of(ref)
        parameters.append({
            "parameter": ref.name,
            "index": ref.index or 0,
            "name": fmt.name,
            "unit": fmt.unit,
            "value": stored_value(row.value if row else None),
            "raw": row.raw if row else None,
            "seen": row.seen if row else None,
            "baseline": stored_value(row.baseline_value if row else None),
            "baseline_since": row.baseline_since if row else None,
            "baseline_by": row.baseline_by if row else None,
            "changed": bool(row and row.changed_seen is not None),
            "changed_seen": row.changed_seen if row else None,
            "factory": _factory(s, ref, fmt),
            "changed_from_factory": s.from_factory.get(ref.pnu),
            "refused": s.refused.get((ref.pnu, ref.index or 0)),
        })  # fmt: skip
    return {
        "drive": s.drive,
        "line": s.line,
        "identity": s.identity,
        "catalog": s.catalog,
        "every": s.every,
        "swept": s.swept,
        "parameters": parameters,
    }


def _factory(s: Swept, ref: ParameterRef, fmt: ParameterDescription) -> Value | None:
    raw = s.factory.get(ref.pnu)
    if raw is None or fmt.vtype is None or isinstance(raw, float):
        return raw
    width = fmt.vtype.width or pkw.Width.DWORD
    try:  # factory_raw gives the number of the type, signed: as it is sent again
        return decode_value(raw & ((1 << width.value) - 1), width, fmt.vtype, fmt.scaling)
    except ValueError:
        return None
