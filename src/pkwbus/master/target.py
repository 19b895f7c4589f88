"""A drive as the line addresses it: protocol, address, dialect, IND layout, block shape.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for an address or dialect the
protocol does not take.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from pkwbus.protocol import pkw
from pkwbus.protocol.buses import (
    DIALECTS_BY_PROTOCOL,
    address_range,
    default_dialect,
    dialect_fits,
)
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect, IndLayout, dialect
from pkwbus.protocol.pkw.length import AUTO, UNKNOWN_SEND_WORDS, PkwSetting, PkwWords
from pkwbus.protocol.profibus.dp.ppo import DEFAULT_PROFILES
from pkwbus.protocol.profidrive.pkw import RecordItem, record_request
from pkwbus.protocol.pzd import MONITORING_CTW, Profile
from pkwbus.protocol.serial.telegram import (
    FC_PARAMETER,
    FC_PROCESS,
    BlockShape,
    FcAddressFormat,
    Protocol,
    encode_block,
    fc_adr,
    frame,
    uss_adr,
)
from pkwbus.protocol.values.types import ValueType

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
    """Everything needed to build a drive's telegrams."""

    protocol: Protocol
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
    adr: int = field(init=False)
    _idle_pzd: tuple[int, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.protocol is Protocol.FC:
            adr = fc_adr(self.address, self.fc_format)
        elif self.protocol is Protocol.PROFIBUS:  # the FDL frame's DA: the station itself
            low, high = address_range(self.protocol)
            if not low <= self.address <= high:
                raise LocalProtocolError(f"DP address {self.address} is outside {low}-{high}")
            adr = self.address
        else:
            low, high = address_range(self.protocol)
            if not low <= self.address <= high:
                raise LocalProtocolError(f"USS address {self.address} is outside {low}-{high}")
            adr = uss_adr(self.address)
        object.__setattr__(self, "adr", adr)
        # PZD: control word with bit 10 = 0 (never take control), reference 0.
        idle = (MONITORING_CTW,) + (0,) * (self.shape.pzd_words - 1) if self.shape.pzd_words else ()
        object.__setattr__(self, "_idle_pzd", idle)

    @classmethod
    def create(
        cls,
        protocol: Protocol | str,
        address: int,
        *,
        dialect_name: str | None = None,
        ind_layout: IndLayout | str | None = None,
        pkw_words: PkwSetting = AUTO,
        pzd_words: int = 2,
        fc_format: FcAddressFormat | str = FcAddressFormat.RANGE_1_126,
    ) -> DriveTarget:
        proto = Protocol(protocol)
        d = dialect(dialect_name or default_dialect(proto))
        if not dialect_fits(proto, d.name):
            known = ", ".join(DIALECTS_BY_PROTOCOL[proto])
            raise LocalProtocolError(f"the {d.name} dialect is not for protocol {proto} ({known})")
        learn = isinstance(pkw_words, str)
        words = UNKNOWN_SEND_WORDS if isinstance(pkw_words, str) else pkw_words
        shape = FC_PARAMETER if proto is Protocol.FC else BlockShape(words, pzd_words)
        layout = IndLayout(ind_layout) if ind_layout is not None else d.default_ind_layout
        learn = learn and proto is Protocol.USS
        return cls(proto, address, d, layout, shape, FcAddressFormat(fc_format), learn)

    @property
    def pkw_setting(self) -> PkwSetting:
        """The PKW length as configured: ``auto`` when it is learned, else the shape's."""
        return AUTO if self.learn else self.shape.pkw_words

    def with_pkw_words(self, words: PkwWords) -> DriveTarget:
        """The same drive with requests of ``words`` PKW words (a learned length)."""
        return replace(self, shape=BlockShape(words, self.shape.pzd_words))

    def pkw_words_of(self, telegram: bytes) -> int:
        """The PKW words of one of this drive's USS request telegrams (STX to BCC)."""
        return (len(telegram) - 4) // 2 - self.shape.pzd_words

    @property
    def profile(self) -> Profile:
        if self.protocol is Protocol.PROFIBUS:
            return DEFAULT_PROFILES.get(self.dialect.name, Profile.PROFIDRIVE)
        return Profile.FC if self.protocol is Protocol.FC else Profile.PROFIDRIVE

    @property
    def has_pkw(self) -> bool:
        return self.shape.pkw_words != 0

    def telegram(self, request: pkw.PkwRequest, vtype: ValueType | None = None) -> bytes:
        """The whole request telegram: PKW, control word with bit 10 = 0, reference 0. For
        a drive reached through data record 47, the parameter request that carries
        ``request`` alone (reference 1; each request sent has its own), its change in the
        format of ``vtype``."""
        if self.record is not None:
            item = RecordItem(request, vtype)
            dialect = self.dialect.name
            return record_request(
                [item], reference=1, axis=self.record.axis, dialect=dialect
            ).encode()
        words = self.shape.pkw_words
        if request.text and (self.protocol is Protocol.FC or self.learn):
            words = None  # a text travels in a block as long as it is
        data = pkw.encode_request(request, self.dialect, self.ind_layout, words)
        if self.protocol is Protocol.PROFIBUS:  # the PPO-write; the DP master frames it
            return encode_block(data, self._idle_pzd)
        return frame(self.adr, encode_block(data, self._idle_pzd))

    def probe(self) -> bytes:
        """The shortest telegram the drive answers: process data only (FC) or PKW AK 0."""
        if self.protocol is Protocol.FC:
            return frame(self.adr, encode_block(b"", (MONITORING_CTW, 0)))
        if not self.has_pkw or self.record is not None:
            return frame(self.adr, encode_block(b"", self._idle_pzd))
        return self.telegram(pkw.none_request(self.dialect))

    def response_shape(self, data_len: int) -> BlockShape:
        """The shape to split a response of ``data_len`` bytes by.

        USS: a drive whose length is learned, or variable, is split by its
        process data alone (the PKW part is the rest, by LGE). A fixed length
        also takes an answer of the other fixed length, 3 or 4 words: that is
        the drive's own length telling against the configured one, which the
        planner reports (its value placed by its LGE); anything else is split
        by the configured shape, and fails there.
        """
        if self.protocol is Protocol.FC:
            if data_len == 4:
                return FC_PROCESS
            return BlockShape(None, 2) if data_len != 12 else FC_PARAMETER
        if self.protocol is not Protocol.USS:
            return self.shape
        pzd = self.shape.pzd_words
        if self.learn or self.shape.pkw_words is None:
            return BlockShape(None, pzd)
        if self.shape.pkw_words and data_len in (2 * (3 + pzd), 2 * (4 + pzd)):
            return BlockShape(data_len // 2 - pzd, pzd)
        return self.shape
