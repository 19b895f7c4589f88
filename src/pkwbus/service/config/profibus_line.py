"""A PROFIBUS DP line: pkwbus its master (its own station, the slot time, the slaves'
watchdog), its drives DP slaves (:mod:`.profibus`) checked by :mod:`.dp_problems`."""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar, Final, Literal

from pydantic import Field, StrictInt

from pkwbus.protocol.buses import DP_MAX_ADDRESS, Bus
from pkwbus.service.config.base import Place, only
from pkwbus.service.config.dp_problems import DpLineSettings, dp_drive_problems
from pkwbus.service.config.fields import SlotTime, Watchdog
from pkwbus.service.config.line import LineBase
from pkwbus.service.config.profibus import ProfibusDrive

__all__ = ["MAX_DP_RETRIES", "ProfibusLine"]

MAX_DP_RETRIES: Final = 8  # a DP slave's request is repeated at most 8 times (DpSlave, SlaveSetup)


class ProfibusLine(LineBase[ProfibusDrive]):
    """A PROFIBUS DP line with pkwbus its master: its characters always 8E1."""

    protocol: Literal[Bus.PROFIBUS]
    refused_keys: ClassVar[Mapping[str, str]] = only(Bus.FC, "fc_address_format")

    # pkwbus's own station, the slot time, the slaves' watchdog.
    master_address: StrictInt = Field(default=2, ge=0, le=DP_MAX_ADDRESS)
    slot_time: SlotTime | None = None
    watchdog: Watchdog | None = None

    def _bus_problems(self) -> list[Place]:
        problems: list[Place] = []
        if self.parity != "E" or self.stopbits != 1:
            problems.append(("parity", "PROFIBUS characters are always 8E1: parity E, stopbits 1"))
        if self.retries > MAX_DP_RETRIES:
            problems.append(("retries", f"at most {MAX_DP_RETRIES} over PROFIBUS"))
        return problems

    def _bus_drive_problems(self, drive: ProfibusDrive) -> list[Place]:
        settings = DpLineSettings(self.master_address, self.baudrate, self.slot_time)
        return dp_drive_problems(settings, drive)
