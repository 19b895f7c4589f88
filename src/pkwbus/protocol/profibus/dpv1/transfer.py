"""One data record written and its answer read back over MSAC_C1, as a state machine
without I/O: how a PROFIdrive parameter request travels (data record 47).

The sequence (SINAMICS G120 operating instructions, "Communication via
PROFIBUS", data set 47; the same for the Danfoss MCA 101): write the request
to slot/index, then read the same record until the response is there. While
it is not, the slave answers the read negatively with "state conflict"
(``DE 80 B5 00``); some slaves answer a short acknowledgement or an answer
without data instead: all three mean "read again". The reads go on until the
response timeout (the GSD's ``C1_Response_Timeout``) has passed since the
write was acknowledged; a write the slave is not ready for is repeated the
same way. Any other negative answer ends the transfer with its reason.

``next_pdu(now)`` says what to send; ``feed(answer, now)`` takes the slave's
answer (a decoded :class:`~pkwbus.protocol.profibus.dpv1.msac.C1Answer`, or :data:`NO_DATA`
for a short acknowledgement or an empty answer) and says when it is over.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dpv1.msac import (
    C1Answer,
    C1Error,
    C1Function,
    Dpv1Setup,
    ReadDone,
    WriteDone,
    read_request,
    write_request,
)

__all__ = ["NO_DATA", "C1Transfer", "NoData", "RecordFailed", "RecordRead", "TransferEnd"]


class NoData(enum.Enum):
    """A short acknowledgement, or an answer without data: not ready."""

    NO_DATA = "no data"


NO_DATA: Final = NoData.NO_DATA


@dataclass(frozen=True, slots=True)
class RecordRead:
    """The record's answer, read back: the response's bytes."""

    data: bytes
    reads: int  # reads it took (1: ready at the first)


@dataclass(frozen=True, slots=True)
class RecordFailed:
    why: str
    error: C1Error | None = None
    timed_out: bool = False


TransferEnd = RecordRead | RecordFailed


class C1Transfer:
    """A write of one record and the read of its answer."""

    def __init__(self, slot: int, index: int, data: bytes, setup: Dpv1Setup, now: float) -> None:
        if len(data) > setup.max_data:
            raise LocalProtocolError(
                f"a record of {len(data)} bytes; the slave takes at most {setup.max_data}"
            )
        self.slot = slot
        self.index = index
        self.setup = setup
        self.function = C1Function.WRITE
        self._write = write_request(slot, index, data)
        self._read = read_request(slot, index, setup.max_data)
        self.deadline = now + setup.response_timeout
        self.reads = 0
        self.end: TransferEnd | None = None

    def next_pdu(self) -> bytes:
        """The MSAC_C1 request to send now (the same again while the slave is not ready)."""
        if self.end is not None:
            raise LocalProtocolError("the transfer is over")
        return self._write if self.function is C1Function.WRITE else self._read

    def feed(self, answer: C1Answer | NoData, now: float) -> TransferEnd | None:
        """The slave's answer to :meth:`next_pdu`; the end once the transfer is over."""
        if self.end is not None:
            raise LocalProtocolError("the transfer is over")
        writing = self.function is C1Function.WRITE
        if not writing:
            self.reads += 1
        if isinstance(answer, WriteDone) and writing:
            self.function = C1Function.READ
            self.deadline = now + self.setup.response_timeout
            return None
        if isinstance(answer, ReadDone) and not writing:
            self.end = RecordRead(answer.data, self.reads)
            return self.end
        if answer is NO_DATA or (isinstance(answer, C1Error) and answer.not_ready):
            if now >= self.deadline:
                what = "write" if writing else "response"
                self.end = RecordFailed(
                    f"the slave had no {what} ready within its response timeout"
                    f" ({self.setup.response_timeout:g} s)", timed_out=True,
                )  # fmt: skip
                return self.end
            return None
        if isinstance(answer, C1Error):
            self.end = RecordFailed(str(answer), answer)
            return self.end
        self.end = RecordFailed(f"{type(answer).__name__} answers a {self.function.name.lower()}")
        return self.end
