"""Lines and drives of the serial telegram buses, Danfoss FC and Siemens USS: each request
one telegram, STX to BCC (:mod:`pkwbus.protocol.serial`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import ClassVar, Final, Literal

from pydantic import Field, StrictInt

from pkwbus.protocol.buses import Bus
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.pkw.length import AUTO, UNKNOWN_SEND_WORDS
from pkwbus.protocol.serial.telegram import FC_PARAMETER, BlockShape, FcAddressFormat
from pkwbus.service.config.base import Place, only
from pkwbus.service.config.drive import DriveBase
from pkwbus.service.config.fields import PkwWords
from pkwbus.service.config.line import LineBase

__all__ = ["DP_DRIVE_KEYS", "DP_LINE_KEYS", "FcDrive", "FcLine", "UssDrive", "UssLine"]

# The settings of a PROFIBUS DP line and drive (:mod:`.profibus_line`, :mod:`.profibus`),
# refused here.
DP_LINE_KEYS: Final = ("master_address", "slot_time", "watchdog")
DP_DRIVE_KEYS: Final = (
    "ppo", "ident", "gsd", "cfg", "user_prm", "dpv1", "parameter_access", "axis",
)  # fmt: skip


class FcDrive(DriveBase):
    """A drive on a Danfoss FC line: its parameter telegrams have one fixed shape."""

    protocol: ClassVar[Literal[Bus.FC]] = Bus.FC
    refused_keys: ClassVar[Mapping[str, str]] = {
        **DriveBase.refused_keys,
        **only(Bus.PROFIBUS, *DP_DRIVE_KEYS),
        **only(Bus.USS, "pkw_words", "pzd_words", why="FC telegrams have a fixed shape"),
    }

    ind_layout: IndLayout | None = None

    @property
    def layout(self) -> IndLayout:
        """The IND layout, given or the dialect's default."""
        return self.ind_layout or self.pkw_dialect.default_ind_layout

    @property
    def shape(self) -> BlockShape:
        """Fixed: FC's parameter telegram."""
        return FC_PARAMETER

    @property
    def sim_shape(self) -> tuple[object, ...]:
        return (self.pkw_dialect.name, self.layout)


class UssDrive(DriveBase):
    """A drive on a Siemens USS line, with the PKW and PZD lengths of its telegrams."""

    protocol: ClassVar[Literal[Bus.USS]] = Bus.USS
    refused_keys: ClassVar[Mapping[str, str]] = {
        **DriveBase.refused_keys,
        **only(Bus.PROFIBUS, *DP_DRIVE_KEYS),
    }

    ind_layout: IndLayout | None = None
    pkw_words: PkwWords = AUTO  # learned from the drive's answers (protocol.pkw_length)
    pzd_words: StrictInt = Field(default=2, ge=0, le=16)

    @property
    def layout(self) -> IndLayout:
        """The IND layout, given or the dialect's default."""
        return self.ind_layout or self.pkw_dialect.default_ind_layout

    @property
    def shape(self) -> BlockShape:
        """As configured (PKW words: :attr:`sent_pkw_words`)."""
        return BlockShape(self.sent_pkw_words, self.pzd_words)

    @property
    def sent_pkw_words(self) -> int | None:
        """The PKW words a request goes out with: configured, or while ``auto`` is not yet
        learned the length both a fixed-4 and a variable drive answer."""
        words = self.pkw_words
        return UNKNOWN_SEND_WORDS if isinstance(words, str) else words

    @property
    def sim_shape(self) -> tuple[object, ...]:
        return (self.pkw_dialect.name, self.layout, self.pkw_words, self.pzd_words)


class FcLine(LineBase[FcDrive]):
    """A Danfoss FC line: its drives at 1-126, or 1-31 with ``fc_address_format: 1-31``."""

    protocol: Literal[Bus.FC]
    refused_keys: ClassVar[Mapping[str, str]] = only(Bus.PROFIBUS, *DP_LINE_KEYS)

    fc_address_format: FcAddressFormat | None = None

    @property
    def address_format(self) -> FcAddressFormat:
        return self.fc_address_format or FcAddressFormat.RANGE_1_126


class UssLine(LineBase[UssDrive]):
    """A Siemens USS line: its drives at 0-30."""

    protocol: Literal[Bus.USS]
    refused_keys: ClassVar[Mapping[str, str]] = {
        **only(Bus.FC, "fc_address_format"),
        **only(Bus.PROFIBUS, *DP_LINE_KEYS),
    }

    def _bus_drive_problems(self, drive: UssDrive) -> list[Place]:
        if drive.pkw_words == 0 and (drive.poll or drive.writable):
            return [("pkw_words", "is 0: the drive has no parameter channel to poll or write")]
        return []
