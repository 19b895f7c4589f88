"""PROFIBUS DP-V1, class 1: the DP-V1 start-up bytes and the acyclic MSAC_C1 read and write.

- **DP-V1 mode** (EN 50170 vol. 2 / IEC 61158-6-3, "Set_Prm"; the slave's GSD,
  keywords ``DPV1_Slave``, ``C1_Read_Write_supp``, ``C1_Max_Data_Len``,
  ``C1_Response_Timeout``): Set_Prm carries DPV1_Status_1, _2 and _3 as its
  first three user parameter bytes; bit 7 of DPV1_Status_1 switches DP-V1 on,
  bit 2 sets the watchdog's time base to 1 ms.
- **MSAC_C1** (the same standard, "MSAC_C1 services"): an SRD request to
  service access point 51 (0x33), answered from SAP 51, in the data exchange
  state only. Function numbers: 0x5E read, 0x5F write. ``5F slot index length
  data`` is answered ``5F slot index length``; ``5E slot index length`` is
  answered ``5E slot index length data``; a negative response is
  ``function | 0x80, Error_Decode, Error_Code_1, Error_Code_2``, where
  Error_Decode 0x80 says "DP-V1" and Error_Code_1 holds the error class (high
  nibble) and code (low nibble), as tabled in :mod:`pkwbus.protocol.profibus.dpv1.errors`.

Pure: bytes in, objects out. :class:`LocalProtocolError` for a request that
cannot be built, :class:`RemoteProtocolError` for an answer that is not one.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus.dpv1.errors import error_code_text, error_decode_text
from pkwbus.protocol.profibus.fdl import DataFrame, Function, request_fc

__all__ = [
    "C1_SAP",
    "DEFAULT_MAX_DATA",
    "DEFAULT_RESPONSE_TIMEOUT",
    "DPV1_ENABLE",
    "NOT_READY",
    "C1Answer",
    "C1Error",
    "C1Function",
    "C1Request",
    "Dpv1Setup",
    "Dpv1Status",
    "ReadDone",
    "WriteDone",
    "decode_c1",
    "decode_c1_request",
    "encode_c1_error",
    "read_request",
    "request_frame",
    "with_dpv1",
    "write_request",
]

C1_SAP: Final = 0x33  # 51: MSAC_C1, on both sides
DPV1_ENABLE: Final = 0x80  # DPV1_Status_1 bit 7
_WD_BASE_1MS: Final = 0x04  # DPV1_Status_1 bit 2
DEFAULT_MAX_DATA: Final = 240  # C1_Max_Data_Len where the GSD names none
DEFAULT_RESPONSE_TIMEOUT: Final = 1.0  # seconds; C1_Response_Timeout where the GSD names none
ERROR_DECODE_DPV1: Final = 0x80
NOT_READY: Final = 0xB5  # Error_Code_1 "state conflict": the response is not there yet
_MAX_SLOT: Final = 254
_MAX_INDEX: Final = 255


@dataclass(frozen=True, slots=True)
class Dpv1Setup:
    """What a DP-V1 slave's GSD says of its class 1 services (``C1_Max_Data_Len``,
    ``C1_Response_Timeout`` in units of 10 ms, ``C1_Read_Write_supp``)."""

    max_data: int = DEFAULT_MAX_DATA
    response_timeout: float = DEFAULT_RESPONSE_TIMEOUT  # seconds
    read_write: bool = True


def with_dpv1(user_prm: bytes, status: Dpv1Status | None = None) -> bytes:
    """A DP-V1 slave's user parameter bytes with DP-V1 switched on: the first three are
    DPV1_Status_1..3 (a GSD's own values are kept, the enable bit set)."""
    status = status or Dpv1Status()
    head = bytearray(user_prm[:3].ljust(3, b"\x00"))
    head[0] |= status.encode()[0]
    return bytes(head) + user_prm[3:]


class C1Function(enum.IntEnum):
    READ = 0x5E
    WRITE = 0x5F


@dataclass(frozen=True, slots=True)
class Dpv1Status:
    """DPV1_Status_1..3, the first three user parameter bytes of a DP-V1 slave's Set_Prm.

    Only the bits pkwbus sets are named: DP-V1 on (bit 7 of the first), and the
    watchdog time base of 1 ms (bit 2); the alarms of DPV1_Status_2 stay off,
    since pkwbus acknowledges none.
    """

    enabled: bool = True
    watchdog_1ms: bool = False

    def encode(self) -> bytes:
        first = (DPV1_ENABLE if self.enabled else 0) | (_WD_BASE_1MS if self.watchdog_1ms else 0)
        return bytes((first, 0, 0))

    @classmethod
    def decode(cls, user_prm: bytes) -> Dpv1Status | None:
        """What the first user parameter bytes say; None when they do not switch DP-V1 on."""
        if len(user_prm) < 3 or not user_prm[0] & DPV1_ENABLE:
            return None
        return cls(True, bool(user_prm[0] & _WD_BASE_1MS))


def _check_slot_index(slot: int, index: int) -> None:
    if not 0 <= slot <= _MAX_SLOT:
        raise LocalProtocolError(f"slot {slot} is outside 0-{_MAX_SLOT}")
    if not 0 <= index <= _MAX_INDEX:
        raise LocalProtocolError(f"index {index} is outside 0-{_MAX_INDEX}")


def read_request(slot: int, index: int, length: int = DEFAULT_MAX_DATA) -> bytes:
    """The data of an MSAC_C1 read of up to ``length`` bytes of record ``index``."""
    _check_slot_index(slot, index)
    if not 1 <= length <= DEFAULT_MAX_DATA:
        raise LocalProtocolError(f"a read of {length} bytes (1-{DEFAULT_MAX_DATA})")
    return bytes((C1Function.READ, slot, index, length))


def write_request(slot: int, index: int, data: bytes) -> bytes:
    """The data of an MSAC_C1 write of ``data`` to record ``index``."""
    _check_slot_index(slot, index)
    if not 1 <= len(data) <= DEFAULT_MAX_DATA:
        raise LocalProtocolError(f"a write of {len(data)} bytes (1-{DEFAULT_MAX_DATA})")
    return bytes((C1Function.WRITE, slot, index, len(data))) + data


def request_frame(slave: int, master: int, pdu: bytes, *, fcb: bool, fcv: bool) -> DataFrame:
    """The SRD frame that carries an MSAC_C1 request to ``slave``."""
    if not 0 <= slave <= 125:
        raise LocalProtocolError(f"slave address {slave} is outside 0-125")
    if not 0 <= master <= 125:
        raise LocalProtocolError(f"master address {master} is outside 0-125")
    fc = request_fc(Function.SRD_HIGH, fcb=fcb, fcv=fcv)
    return DataFrame(slave, master, fc, C1_SAP, C1_SAP, pdu)


# ----------------------------------------------------------------- answers


@dataclass(frozen=True, slots=True)
class ReadDone:
    slot: int
    index: int
    data: bytes


@dataclass(frozen=True, slots=True)
class WriteDone:
    slot: int
    index: int
    length: int


@dataclass(frozen=True, slots=True)
class C1Error:
    """A negative MSAC_C1 response."""

    function: C1Function
    decode: int  # Error_Decode: 0x80 DP-V1
    code1: int  # Error_Code_1: class << 4 | code
    code2: int  # Error_Code_2: the slave's own

    @property
    def not_ready(self) -> bool:
        """ "State conflict": the slave has no response yet; read again."""
        return self.decode == ERROR_DECODE_DPV1 and self.code1 == NOT_READY

    @property
    def text(self) -> str:
        if self.decode != ERROR_DECODE_DPV1:
            return (
                f"{error_decode_text(self.decode)}, error codes {self.code1:#04x} {self.code2:#04x}"
            )
        more = f" (slave's code {self.code2:#04x})" if self.code2 else ""
        return f"{error_code_text(self.code1)}{more}"

    def __str__(self) -> str:
        return f"DP-V1 {self.function.name.lower()} refused: {self.text}"


C1Answer = ReadDone | WriteDone | C1Error


def decode_c1(data: bytes, function: C1Function, slot: int, index: int) -> C1Answer:
    """The slave's answer to an MSAC_C1 ``function`` on ``slot``/``index``."""
    if not data:
        raise RemoteProtocolError("an MSAC_C1 answer without data")
    head = data[0]
    if head == function | 0x80:
        if len(data) != 4:
            raise RemoteProtocolError(f"a negative MSAC_C1 response of {len(data)} bytes (4)")
        return C1Error(function, data[1], data[2], data[3])
    if head != function:
        raise RemoteProtocolError(f"MSAC_C1 function {head:#04x} answers {function:#04x}")
    if len(data) < 4:
        raise RemoteProtocolError(f"an MSAC_C1 response of {len(data)} bytes (at least 4)")
    if (data[1], data[2]) != (slot, index):
        raise RemoteProtocolError(
            f"an answer for slot {data[1]} index {data[2]}, asked slot {slot} index {index}"
        )
    length = data[3]
    if function is C1Function.WRITE:
        if len(data) != 4:
            raise RemoteProtocolError(f"a write response of {len(data)} bytes (4)")
        return WriteDone(slot, index, length)
    if len(data) != 4 + length:
        raise RemoteProtocolError(f"a read response of {len(data) - 4} bytes, {length} said")
    return ReadDone(slot, index, bytes(data[4:]))


# ------------------------------------------------------------- the slave's side


@dataclass(frozen=True, slots=True)
class C1Request:
    function: C1Function
    slot: int
    index: int
    length: int
    data: bytes = b""


def decode_c1_request(data: bytes) -> C1Request:
    """An MSAC_C1 request as a slave receives it (the simulator's side, and tests)."""
    if len(data) < 4:
        raise RemoteProtocolError(f"an MSAC_C1 request of {len(data)} bytes (at least 4)")
    try:
        function = C1Function(data[0])
    except ValueError:
        raise RemoteProtocolError(f"MSAC_C1 function {data[0]:#04x}") from None
    slot, index, length = data[1], data[2], data[3]
    if function is C1Function.WRITE:
        if len(data) != 4 + length:
            raise RemoteProtocolError(f"a write of {len(data) - 4} bytes, {length} said")
        return C1Request(function, slot, index, length, bytes(data[4:]))
    if len(data) != 4:
        raise RemoteProtocolError(f"a read request of {len(data)} bytes (4)")
    return C1Request(function, slot, index, length)


def encode_c1_error(function: C1Function, code1: int, code2: int = 0) -> bytes:
    """A DP-V1 negative response (the simulator's side, and tests)."""
    return bytes((function | 0x80, ERROR_DECODE_DPV1, code1, code2))
