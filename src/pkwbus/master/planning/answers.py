"""What comes back of one exchange, as the planner is given it: the drive's reply as it came
(its bytes, decoded once by the job's carrier), or why there was none; a PKW answer is what
a carrier decodes a reply into."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from pkwbus.protocol import pkw

__all__ = ["ErrorKind", "ExchangeResult", "Failure", "PkwAnswer", "Reply"]


class ErrorKind(enum.StrEnum):
    """Why one exchange produced no usable answer (the metric's ``kind`` label)."""

    TIMEOUT = "timeout"
    CHECKSUM = "checksum"
    LENGTH = "length"
    ADDRESS = "address"
    UNEXPECTED = "unexpected"
    PORT = "port"


@dataclass(frozen=True, slots=True)
class Reply:
    """A valid frame from the addressed drive: its data (a telegram's block, a data
    record), for the job's carrier to decode; ``duration`` from the request written."""

    adr: int
    data: bytes
    duration: float


@dataclass(frozen=True, slots=True)
class PkwAnswer:
    """A PKW answer decoded once by its carrier, with the process data beside it.

    ``response`` None: the drive answered, but not with a PKW answer of its dialect
    (``why``): a try of the job's retries, as a telegram that does not decode.
    """

    response: pkw.PkwResponse | None
    pkw: bytes  # as it came, for a stale answer's comparison (empty where none is kept)
    status_word: int | None
    main_actual: int | None
    duration: float
    # No AK 0 was seen since the request went in: it may still answer an earlier one.
    earlier: bool = False
    why: str = ""


@dataclass(frozen=True, slots=True)
class Failure:
    kind: ErrorKind
    detail: str = ""


ExchangeResult = Reply | Failure
