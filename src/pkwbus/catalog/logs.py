"""The logs each drive family keeps, by its catalog: which of the drives' own logs
(:mod:`pkwbus.protocol.logs`) a drive of that catalog is watched through."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Final

from pkwbus.protocol.logs import (
    DANFOSS_ALARM_LOG,
    SINAMICS_ALARM_BUFFER,
    SINAMICS_FAULT_BUFFER,
    DriveLog,
)

__all__ = ["LOGS", "logs_of_catalog"]

LOGS: Final[Mapping[str, tuple[DriveLog, ...]]] = MappingProxyType(
    {
        "danfoss-fc": (DANFOSS_ALARM_LOG,),
        "siemens-g120": (SINAMICS_FAULT_BUFFER, SINAMICS_ALARM_BUFFER),
    }
)


def logs_of_catalog(catalog: str | None) -> tuple[DriveLog, ...]:
    """The logs of a drive of ``catalog`` (none: no catalog, or none known for it)."""
    return LOGS.get(catalog, ()) if catalog is not None else ()
