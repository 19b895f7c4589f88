"""Several PKW jobs of one drive as one PROFIdrive parameter request (data record 47),
as a state machine without I/O.

The planner's work stays in PKW terms (a poll's read, a job's change, a
description element); here each becomes one parameter of a base mode request
(:mod:`pkwbus.protocol.profidrive.parameters`), and each parameter of the response comes
back as what the PKW channel would have answered: a value (with the type the
drive names: a float is a float), a description element, the drive's error
number as a refusal, or a change done (no value echoed). The wire carries the
request as a record transfer (write, read until ready); a transfer that fails
or a response that is not this request's answer is tried again, the same
request, up to ``retries`` times; then every job of it ends timed out.

How a PKW request becomes a parameter of the request:
:mod:`pkwbus.protocol.profidrive.pkw`.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from pkwbus.master.planning.outcomes import Answered, LineFailed, Outcome, Rejected, TimedOut
from pkwbus.master.planning.transaction import ErrorKind, ExchangeResult, Failure, PkwAnswer, Tally
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Command, Reply
from pkwbus.protocol.pkw.fields import Width
from pkwbus.protocol.profidrive import parameters as profidrive
from pkwbus.protocol.profidrive.errors import error_text
from pkwbus.protocol.profidrive.parameters import Format, ParameterError
from pkwbus.protocol.profidrive.pkw import RecordItem, record_request
from pkwbus.protocol.values.types import ValueType

__all__ = ["RecordItem", "RecordTransaction"]

# The value types the typed formats name. Byte, Word and Double word are substitutes that
# name no type: there the configuration, the description or the catalog decides.
_TYPES = {
    Format.BOOLEAN: ValueType.U16, Format.U8: ValueType.U16, Format.U16: ValueType.U16,
    Format.I8: ValueType.I16, Format.I16: ValueType.I16, Format.U32: ValueType.U32,
    Format.I32: ValueType.I32, Format.FLOAT: ValueType.F32,
}  # fmt: skip


class RecordTransaction:
    """Feed it exchange results; it says when the request is done, and each job's outcome."""

    def __init__(
        self,
        target: DriveTarget,
        items: Sequence[RecordItem],
        *,
        reference: int,
        axis: int,
        retries: int,
        deadline: float,
    ) -> None:
        self.target = target
        self.items = tuple(items)
        self.request = record_request(
            self.items, reference=reference, axis=axis, dialect=target.dialect.name
        )
        self.telegram = self.request.encode()
        self.retries = retries
        self.deadline = deadline
        self.tally = Tally()
        self.waiting = False
        self.outcome: Outcome | None = None
        self.outcomes: tuple[Outcome, ...] = ()
        self._failures = 0

    def feed(self, result: ExchangeResult, now: float) -> Outcome | None:
        """Account for one record transfer; once the request is finished, the first job's
        outcome (each job's is in :attr:`outcomes`)."""
        tally = self.tally
        tally.telegrams += 1
        if isinstance(result, PkwAnswer):
            raise LocalProtocolError("a record transfer answers with a record, not a PKW answer")
        if isinstance(result, Failure):
            tally.errors[result.kind] += 1
            if result.kind is ErrorKind.PORT:
                return self._end(LineFailed(result.detail))
            return self._try_again(f"no answer ({result.kind.value}: {result.detail})", now)
        tally.busy += result.duration
        try:
            response = profidrive.decode_response(result.data, self.request)
        except RemoteProtocolError as exc:
            tally.errors[ErrorKind.UNEXPECTED] += 1
            return self._try_again(str(exc), now)
        outcomes = tuple(
            self._outcome(item, got) for item, got in zip(self.items, response.results, strict=True)
        )
        return self._end(outcomes[0], outcomes)

    def _try_again(self, why: str, now: float) -> Outcome | None:
        self._failures += 1
        if self._failures > self.retries or now >= self.deadline:
            return self._end(TimedOut(f"no parameter response after {self._failures} tries: {why}"))
        tally = self.tally
        tally.retries += 1
        return None

    def _end(self, outcome: Outcome, outcomes: tuple[Outcome, ...] | None = None) -> Outcome:
        self.outcome = outcome
        self.outcomes = outcomes if outcomes is not None else (outcome,) * len(self.items)
        return outcome

    def _outcome(self, item: RecordItem, got: profidrive.Result) -> Outcome:
        request = item.request
        dialect = self.target.dialect
        if isinstance(got, ParameterError):
            text = error_text(got.number, dialect.name)
            return Rejected(got.number, text, text)
        if got is None:
            return Answered(pkw.ChangeDone(0, request.pnu, request.subindex))
        if got.format in (Format.OCTET_STRING, Format.VISIBLE_STRING):
            (data,) = got.values
            assert isinstance(data, bytes)
            if request.command is Command.READ_DESCRIPTION:
                ak = pkw.response_id(dialect, Reply.DESCRIPTION)
                raw = int.from_bytes(data, "big") if len(data) <= 4 else 0
                return Answered(
                    pkw.DescriptionResponse(ak, request.pnu, request.subindex, raw, data)
                )
            return Answered(pkw.TextResponse(pkw.response_id(dialect, Reply.TEXT), request.pnu,
                                             request.subindex, data))  # fmt: skip
        if got.format is Format.ZERO or not got.values:
            return Answered(pkw.ChangeDone(0, request.pnu, request.subindex))
        value = got.values[0]
        width = Width.WORD if got.format.size <= 2 else Width.DWORD
        if isinstance(value, float):
            raw = int.from_bytes(struct.pack(">f", value), "big")
        elif isinstance(value, int):
            raw = value & (0xFFFF if width is Width.WORD else 0xFFFFFFFF)
        else:
            raise RemoteProtocolError(f"a {got.format.name} value of parameter {request.pnu}")
        if request.command is Command.READ_DESCRIPTION:
            ak = pkw.response_id(dialect, Reply.DESCRIPTION)
            data = raw.to_bytes(2 if width is Width.WORD else 4, "big")
            return Answered(pkw.DescriptionResponse(ak, request.pnu, request.subindex, raw, data,
                                                    width))  # fmt: skip
        reply = Reply.WORD if width is Width.WORD else Reply.DWORD
        ak = pkw.response_id(dialect, reply)
        vtype = _TYPES.get(got.format)
        return Answered(pkw.ValueResponse(ak, request.pnu, request.subindex, raw, width, vtype))
