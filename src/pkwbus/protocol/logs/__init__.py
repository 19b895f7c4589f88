"""What a drive remembers: its own fault and alarm logs, read through the PKW channel.

Pure: which parameters to read (:class:`Read`), and what their values say
(:class:`LogEntry`). Each log is laid out as its vendor's document defines
it: the SINAMICS fault buffer (:data:`SINAMICS_FAULT_BUFFER`), the Danfoss
FC alarm log (:data:`DANFOSS_ALARM_LOG`), the SINAMICS alarm buffer
(:data:`SINAMICS_ALARM_BUFFER`). A log is watched cheaply (its
change counter, or its newest entry) and swept whole only when that changed;
a sweep is a few rounds of reads, each decided by what the earlier ones said
(:class:`Sweep`). Entries are told apart by their content (kind, code, value,
drive time), never by their index, which shifts with every new entry.
"""

from pkwbus.protocol.logs.danfoss import DANFOSS_ALARM_LOG
from pkwbus.protocol.logs.micromaster import MICROMASTER_FAULT_BUFFER
from pkwbus.protocol.logs.model import (
    Age,
    DriveLog,
    Kind,
    LogEntry,
    NoSuchLog,
    Opaque,
    Read,
    Runtime,
    Sweep,
    SweepResult,
    TimeBase,
)
from pkwbus.protocol.logs.profidrive import PROFIDRIVE_FAULT_BUFFER
from pkwbus.protocol.logs.sinamics import SINAMICS_FAULT_BUFFER
from pkwbus.protocol.logs.sinamics_alarms import SINAMICS_ALARM_BUFFER

__all__ = [
    "DANFOSS_ALARM_LOG",
    "MICROMASTER_FAULT_BUFFER",
    "PROFIDRIVE_FAULT_BUFFER",
    "SINAMICS_ALARM_BUFFER",
    "SINAMICS_FAULT_BUFFER",
    "Age",
    "DriveLog",
    "Kind",
    "LogEntry",
    "NoSuchLog",
    "Opaque",
    "Read",
    "Runtime",
    "Sweep",
    "SweepResult",
    "TimeBase",
]
