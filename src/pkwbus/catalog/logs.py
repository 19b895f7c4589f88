"""The logs each drive family keeps, by its catalog: which of the drives' own logs
(:mod:`pkwbus.protocol.logs`) a drive of that catalog is watched through; and a PROFIBUS
drive of the ``profidrive`` dialect whose catalog keeps none, the PROFIdrive fault buffer
of any make (:func:`logs_of_drive`)."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Final

from pkwbus.protocol.buses import Bus
from pkwbus.protocol.logs import (
    DANFOSS_ALARM_LOG,
    MICROMASTER_FAULT_BUFFER,
    PROFIDRIVE_FAULT_BUFFER,
    SINAMICS_ALARM_BUFFER,
    SINAMICS_FAULT_BUFFER,
    DriveLog,
)

__all__ = ["LOGS", "logs_of_catalog", "logs_of_drive"]

LOGS: Final[Mapping[str, tuple[DriveLog, ...]]] = MappingProxyType(
    {
        "danfoss-fc": (DANFOSS_ALARM_LOG,),
        "siemens-g120": (SINAMICS_FAULT_BUFFER, SINAMICS_ALARM_BUFFER),
        "siemens-mm4": (MICROMASTER_FAULT_BUFFER,),
    }
)


def logs_of_catalog(catalog: str | None) -> tuple[DriveLog, ...]:
    """The logs of a drive of ``catalog`` (none: no catalog, or none known for it)."""
    return LOGS.get(catalog, ()) if catalog is not None else ()


def logs_of_drive(catalog: str | None, protocol: Bus, dialect: str) -> tuple[DriveLog, ...]:
    """The logs of a drive: its catalog's; where that keeps none, a PROFIBUS drive of the
    ``profidrive`` dialect has the PROFIdrive fault buffer (watched where it answers P944
    and P950: :mod:`pkwbus.protocol.logs.profidrive`)."""
    own = logs_of_catalog(catalog)
    if own or protocol is not Bus.PROFIBUS or dialect != "profidrive":
        return own
    return (PROFIDRIVE_FAULT_BUFFER,)
