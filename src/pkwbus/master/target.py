"""A drive as the line addresses it: protocol, address, dialect, IND layout, block shape.

What the drive is, never how its requests travel: each carrier builds those
(:mod:`pkwbus.master.carriers`), and what differs by bus is asked of
:mod:`pkwbus.protocol.buses`; nothing here branches on the bus.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for an address or dialect the
protocol does not take.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from pkwbus.protocol.buses import (
    DIALECTS_BY_PROTOCOL,
    FIXED_SHAPES,
    LEARNED_LENGTH,
    Bus,
    check_address,
    default_dialect,
    dialect_fits,
    profile,
)
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect, IndLayout, dialect
from pkwbus.protocol.pkw.length import AUTO, UNKNOWN_SEND_WORDS, PkwSetting, PkwWords
from pkwbus.protocol.pzd import Profile
from pkwbus.protocol.serial.telegram import BlockShape, FcAddressFormat

__all__ = [
    "DriveTarget",
    "RecordAccess",
]


@dataclass(frozen=True, slots=True)
class RecordAccess:
    """A DP-V1 slave whose parameters go through PROFIdrive data record 47 (many in one
    request) instead of its PPO's PKW words: its axis (drive object) and slot."""

    axis: int
    slot: int = 0
    max_data: int = 240  # C1_Max_Data_Len: the largest record the slave takes, in bytes


@dataclass(frozen=True)
class DriveTarget:
    """Everything its carrier needs to build a drive's requests."""

    protocol: Bus
    address: int
    dialect: Dialect
    ind_layout: IndLayout
    shape: BlockShape
    fc_format: FcAddressFormat = FcAddressFormat.RANGE_1_126
    # USS: the PKW length is learned from the drive's answers (configured ``auto``);
    # ``shape`` is what requests go out with meanwhile (see protocol.pkw_length).
    learn: bool = False
    # PROFIBUS DP-V1: parameters through data record 47 (None: through PKW).
    record: RecordAccess | None = None

    def __post_init__(self) -> None:
        check_address(self.protocol, self.address, self.fc_format)

    @classmethod
    def create(
        cls,
        protocol: Bus | str,
        address: int,
        *,
        dialect_name: str | None = None,
        ind_layout: IndLayout | str | None = None,
        pkw_words: PkwSetting = AUTO,
        pzd_words: int = 2,
        fc_format: FcAddressFormat | str = FcAddressFormat.RANGE_1_126,
    ) -> DriveTarget:
        proto = Bus(protocol)
        d = dialect(dialect_name or default_dialect(proto))
        if not dialect_fits(proto, d.name):
            known = ", ".join(DIALECTS_BY_PROTOCOL[proto])
            raise LocalProtocolError(f"the {d.name} dialect is not for protocol {proto} ({known})")
        learn = isinstance(pkw_words, str) and proto in LEARNED_LENGTH
        words = UNKNOWN_SEND_WORDS if isinstance(pkw_words, str) else pkw_words
        shape = FIXED_SHAPES.get(proto) or BlockShape(words, pzd_words)
        layout = IndLayout(ind_layout) if ind_layout is not None else d.default_ind_layout
        return cls(proto, address, d, layout, shape, FcAddressFormat(fc_format), learn)

    @property
    def pkw_setting(self) -> PkwSetting:
        """The PKW length as configured: ``auto`` when it is learned, else the shape's."""
        return AUTO if self.learn else self.shape.pkw_words

    def with_pkw_words(self, words: PkwWords) -> DriveTarget:
        """The same drive with requests of ``words`` PKW words (a learned length)."""
        return replace(self, shape=BlockShape(words, self.shape.pzd_words))

    @property
    def profile(self) -> Profile:
        """The profile of its control and status words."""
        return profile(self.protocol, self.dialect.name)

    @property
    def has_pkw(self) -> bool:
        return self.shape.pkw_words != 0
