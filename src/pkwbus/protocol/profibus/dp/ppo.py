"""PPO types and the PKW parameter channel inside PROFIBUS DP cyclic data.

A PPO (parameter process data object, PROFIdrive profile; Danfoss PROFIBUS
programming guide, "PPO types"; Siemens CU240 operating instructions,
"communication via PROFIBUS") is the Data_Exchange data: the PKW words first
(PPO 1, 2 and 5), then the PZD words, all big endian. The master sends the
PPO-write, the slave answers with the PPO-read.

pkwbus never takes control of a drive: every PPO-write carries a control
word of 0 (bit 10 "control by PLC" / "data valid" clear) and every other PZD
word 0. This is enforced here and cannot be changed by a caller.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a PPO or dialect that
cannot be used and :class:`~pkwbus.protocol.errors.RemoteProtocolError` for a PPO-read
that does not decode.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from pkwbus.protocol import pkw, pzd
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Command, Dialect, IndLayout, dialect
from pkwbus.protocol.pzd import Profile

__all__ = [
    "DEFAULT_PROFILES",
    "DP_DIALECTS",
    "IDLE_WAIT_CYCLES",
    "LAYOUT",
    "PKW_WORDS",
    "PPO_TYPES",
    "PkwSlot",
    "PpoRead",
    "PpoType",
    "SlotAnswer",
    "SlotGarbled",
    "SlotUpdate",
    "decode_ppo_read",
    "dp_dialect",
    "encode_ppo_write",
    "ppo_type",
    "pzd_words",
]

DP_DIALECTS: Final = ("profidrive", "danfoss-pcv", "hitachi-sjpb")
LAYOUT: Final = IndLayout.PROFIDRIVE  # subindex in IND high byte, page index in the low byte
PKW_WORDS: Final = 4
IDLE_WAIT_CYCLES: Final = 10  # cycles a new job waits for the slave's AK 0 at most


@dataclass(frozen=True, slots=True)
class PpoType:
    """One PPO: its PKW and PZD word counts and its configuration identifiers."""

    number: int
    pkw_words: int
    pzd_words: int
    cfg: bytes

    @property
    def length(self) -> int:
        """Bytes of a PPO-write (and of a PPO-read)."""
        return 2 * (self.pkw_words + self.pzd_words)

    @property
    def has_pkw(self) -> bool:
        return self.pkw_words > 0


# Configuration identifiers as in the Danfoss GSD: F3 = 4 words in/out consistent (PKW),
# F1/F5/F9 = 2/6/10 words in/out consistent (PZD).
PPO_TYPES: Mapping[int, PpoType] = MappingProxyType(
    {
        1: PpoType(1, 4, 2, b"\xf3\xf1"),
        2: PpoType(2, 4, 6, b"\xf3\xf5"),
        3: PpoType(3, 0, 2, b"\xf1"),
        4: PpoType(4, 0, 6, b"\xf5"),
        5: PpoType(5, 4, 10, b"\xf3\xf9"),
    }
)

DEFAULT_PROFILES: Mapping[str, Profile] = MappingProxyType(
    {
        "profidrive": Profile.PROFIDRIVE,
        "danfoss-pcv": Profile.FC,
        "hitachi-sjpb": Profile.PROFIDRIVE,
    }
)


def ppo_type(number: int) -> PpoType:
    try:
        return PPO_TYPES[number]
    except KeyError:
        raise LocalProtocolError(f"PPO {number} is not one of 1-5") from None


def dp_dialect(name: str) -> Dialect:
    """A PKW dialect usable inside PPOs."""
    if name not in DP_DIALECTS:
        raise LocalProtocolError(
            f"dialect {name!r} is not used over PROFIBUS (known: {', '.join(DP_DIALECTS)})"
        )
    return dialect(name)


# ------------------------------------------------------------------ PPO-write


def encode_ppo_write(ppo: PpoType, dia: Dialect, request: pkw.PkwRequest | None = None) -> bytes:
    """The PPO-write: the PKW request (AK 0 when None), then a zero control word and zero PZD.

    The control word is :data:`pzd.MONITORING_CTW` (bit 10 clear): the drive
    ignores the process data, so pkwbus never controls a motor.
    """
    if dia.name not in DP_DIALECTS:
        raise LocalProtocolError(f"dialect {dia.name!r} is not used over PROFIBUS")
    if not ppo.has_pkw:
        if request is not None and request.command is not Command.NONE:
            raise LocalProtocolError(f"PPO {ppo.number} has no parameter channel")
        head = b""
    else:
        if request is not None and request.text:
            raise LocalProtocolError("a text write does not fit the 4 PKW words of a PPO")
        req = request if request is not None else pkw.none_request(dia)
        head = pkw.encode_request(req, dia, LAYOUT, PKW_WORDS)
    ctw = pzd.MONITORING_CTW
    assert not pzd.takes_control(ctw)
    return head + ctw.to_bytes(2, "big") + bytes(2 * (ppo.pzd_words - 1))


# ------------------------------------------------------------------- PPO-read


@dataclass(frozen=True, slots=True)
class PpoRead:
    """A decoded PPO-read: the PKW answer (None in PPO 3/4) and the PZD words."""

    pkw: pkw.PkwResponse | None
    pzd: tuple[int, ...]
    profile: Profile

    @property
    def status_word(self) -> int:
        return self.pzd[0]

    @property
    def main_actual_value(self) -> int:
        return self.pzd[1]

    @property
    def status(self) -> dict[str, bool]:
        """The status word's named bits in the drive's profile."""
        return pzd.status_bits(self.status_word, self.profile)

    @property
    def main_actual_percent(self) -> float:
        """The main actual value as percent (0x4000 = 100 %)."""
        return pzd.ref_to_percent(self.main_actual_value)


def decode_ppo_read(
    ppo: PpoType, dia: Dialect, data: bytes, profile: Profile | None = None
) -> PpoRead:
    """Decode a PPO-read; the peer's error for a wrong length or an unknown identifier."""
    if len(data) != ppo.length:
        raise RemoteProtocolError(
            f"PPO-read of {len(data)} bytes, PPO {ppo.number} has {ppo.length}"
        )
    cut = 2 * ppo.pkw_words
    response = pkw.decode_response(data[:cut], dia, LAYOUT) if ppo.has_pkw else None
    words = pzd_words(ppo, data)
    return PpoRead(response, words, profile or DEFAULT_PROFILES.get(dia.name, Profile.PROFIDRIVE))


def pzd_words(ppo: PpoType, data: bytes) -> tuple[int, ...]:
    """The PZD words of a PPO-read (status word, main actual value, ...): what follows its
    PKW words. The one place they are cut out of the bytes."""
    cut = 2 * ppo.pkw_words
    return tuple(int.from_bytes(data[i : i + 2], "big") for i in range(cut, len(data) - 1, 2))


# ------------------------------------------------------------------ PKW slot


@dataclass(frozen=True, slots=True)
class SlotAnswer:
    """The PKW answer of a PPO-read while the slot carried a request: whether it is the
    request's answer, "not yet" or a mismatch is the job's to judge (one rule for every
    bus: :func:`pkw.judge`, in the master's transaction). ``earlier``: the slave showed
    no AK 0 since the request went in, so this may still be its answer to an earlier,
    identical request."""

    request: pkw.PkwRequest
    response: pkw.PkwResponse
    earlier: bool
    read: PpoRead


@dataclass(frozen=True, slots=True)
class SlotGarbled:
    """A PPO-read whose PKW words are no answer of the slot's dialect (the slave set to
    another PPO or dialect, say): ``request`` is the one the slot carried when it came
    (None: none went out yet, the slot was waiting for AK 0)."""

    request: pkw.PkwRequest | None
    why: str


@dataclass(frozen=True, slots=True)
class SlotUpdate:
    """What one PPO-read brought: its bytes, the decoded read (None when undecodable), the
    answer to the request the slot carries (None: none went out, or it was AK 0 waiting),
    why the read could not be decoded, and its PZD words (cut once, here; empty when the
    read is not of the PPO's length)."""

    inputs: bytes
    read: PpoRead | None
    answer: SlotAnswer | None
    garbled: SlotGarbled | None = None
    pzd: tuple[int, ...] = ()

    @property
    def error(self) -> str:
        return self.garbled.why if self.garbled is not None else ""


class PkwSlot:
    """The parameter channel of one slave over DP: the request of one job, in every
    PPO-write until the job is finished (:meth:`finish`); with no job, AK 0.

    Before a new request the slot waits for the slave to answer AK 0 (at most
    :data:`IDLE_WAIT_CYCLES` cycles), so that the answer to an earlier identical
    request is not taken for the new one's (Siemens CU240 operating instructions,
    "rules for editing requests and responses"). Whether an answer ends the job
    is not the slot's to say.
    """

    def __init__(self, ppo: PpoType, dia: Dialect, profile: Profile | None = None) -> None:
        if dia.name not in DP_DIALECTS:
            raise LocalProtocolError(f"dialect {dia.name!r} is not used over PROFIBUS")
        self.ppo = ppo
        self.dialect = dia
        self.profile = profile or DEFAULT_PROFILES[dia.name]
        self.request: pkw.PkwRequest | None = None
        self.update: SlotUpdate | None = None  # what the latest PPO-read brought
        # The two PPO-writes it sends, each encoded once: AK 0, and its job's request.
        self._idle = encode_ppo_write(ppo, dia) if ppo.has_pkw else b""
        self._write = b""
        self.cycles = 0  # PPO-reads since the request was submitted
        self._idle_seen = False
        self._idle_cycles = 0

    @property
    def busy(self) -> bool:
        return self.request is not None

    def submit(self, request: pkw.PkwRequest, write: bytes | None = None) -> None:
        """Carry ``request`` from the next PPO-write on; ``write`` is that PPO-write as its
        carrier already encoded it (:func:`encode_ppo_write` of the same request; encoded
        here when None), sent as it is every cycle until :meth:`finish`."""
        if not self.ppo.has_pkw:
            raise LocalProtocolError(f"PPO {self.ppo.number} has no parameter channel")
        if self.request is not None:
            raise LocalProtocolError("a parameter job is already under way on this slave")
        if request.command is Command.NONE:
            raise LocalProtocolError("AK 0 is not a job")
        if request.text:
            raise LocalProtocolError("a text write does not fit the 4 PKW words of a PPO")
        if write is None:
            write = encode_ppo_write(self.ppo, self.dialect, request)
        elif len(write) != self.ppo.length:
            raise LocalProtocolError(
                f"a PPO {self.ppo.number} write is {self.ppo.length} bytes, not {len(write)}"
            )
        self.request = request
        self._write = write
        self.cycles = 0

    def finish(self) -> None:
        """The job is over (answered, refused, mismatched or past its deadline): AK 0
        goes out again, and the next job waits for the slave's AK 0."""
        self.request = None
        self._write = b""
        self._idle_seen = False
        self._idle_cycles = 0

    def _sending(self) -> pkw.PkwRequest | None:
        if self.request is not None and (self._idle_seen or self._idle_cycles >= IDLE_WAIT_CYCLES):
            return self.request
        return None

    def outputs(self) -> bytes:
        """The PPO-write for the next Data_Exchange (encoded once per job, not per cycle)."""
        return self._write if self._sending() is not None else self._idle

    def feed(self, inputs: bytes) -> SlotUpdate:
        """Take the PPO-read answering the last :meth:`outputs`, decoded once: what it
        brought is also kept as :attr:`update` until the next."""
        self.update = update = self._feed(inputs)
        return update

    def _feed(self, inputs: bytes) -> SlotUpdate:
        sent = self._sending()
        if self.request is not None:
            self.cycles += 1
        try:
            read = decode_ppo_read(self.ppo, self.dialect, inputs, self.profile)
        except RemoteProtocolError as exc:
            if sent is None and self.request is not None:
                self._idle_cycles += 1  # not AK 0: the wait for it runs out as for any other
            why = f"its PPO-read is no PPO {self.ppo.number} answer of the {self.dialect.name}"
            garbled = SlotGarbled(sent, f"{why} dialect ({exc})")
            words = pzd_words(self.ppo, inputs) if len(inputs) == self.ppo.length else ()
            return SlotUpdate(inputs, None, None, garbled, words)
        response, words = read.pkw, read.pzd
        if sent is None:
            if isinstance(response, pkw.NoResponse):
                self._idle_seen = True
            else:
                self._idle_cycles += 1
            return SlotUpdate(inputs, read, None, pzd=words)
        if response is None:
            return SlotUpdate(inputs, read, None, pzd=words)
        answer = SlotAnswer(sent, response, not self._idle_seen, read)
        return SlotUpdate(inputs, read, answer, pzd=words)
