"""PKW jobs in PROFIdrive data record 47 (DP-V1 class 1): several parameters in one request.

The planner's work stays in PKW terms (a poll's read, a job's change, a
description element); here each becomes one parameter of a base mode request
(:mod:`pkwbus.protocol.profidrive.pkw`), and each parameter of the response
comes back as what the PKW channel would have answered: a value (with the
type the drive names: a float is a float), a description element, the drive's
error number as a refusal, or a change done (no value echoed). Each request
has a reference of its own (1-255, round), which its response must mirror.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from pkwbus.master.carriers.slave import SlaveHealth
from pkwbus.master.planning.carrier import Item, Preview
from pkwbus.master.planning.outcomes import Answered, Outcome, Rejected
from pkwbus.master.planning.transaction import BatchTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Command, Dialect, Reply
from pkwbus.protocol.profidrive import parameters as profidrive
from pkwbus.protocol.profidrive.errors import error_text
from pkwbus.protocol.profidrive.parameters import Format, ParameterError, ParameterRequest
from pkwbus.protocol.profidrive.pkw import RecordItem, carried, fits, record_request
from pkwbus.protocol.values.types import ValueType, Width

__all__ = ["RecordCarrier"]

# The value types the typed formats name. Byte, Word and Double word are substitutes that
# name no type: there the configuration, the description or the catalog decides.
_TYPES = {
    Format.BOOLEAN: ValueType.U16, Format.U8: ValueType.U16, Format.U16: ValueType.U16,
    Format.I8: ValueType.I16, Format.I16: ValueType.I16, Format.U32: ValueType.U32,
    Format.I32: ValueType.I32, Format.FLOAT: ValueType.F32,
}  # fmt: skip


class RecordCarrier(SlaveHealth):
    """A DP-V1 slave's parameters through data record 47: its axis, slot and largest
    record."""

    texts = False
    repeats_answers = False  # a response answers its own request reference

    def __init__(
        self,
        address: int,
        dialect: Dialect,
        axis: int,
        max_data: int = 240,
        slot: int = 0,
        *,
        first_reference: int = 1,
    ) -> None:
        self.address = address
        self.dialect = dialect
        self.axis = axis  # the drive object the requests address
        self.max_data = max_data  # C1_Max_Data_Len: the largest record the slave takes
        self.slot = slot  # the MSAC_C1 slot of data record 47
        self._reference = (first_reference - 1) % 255 + 1  # the next request's

    def room(self, count: int) -> bool:
        return fits(count, self.max_data)

    def refuses(self, request: pkw.PkwRequest) -> str:
        return carried(request)

    def preview(self, item: Item) -> Preview:
        """The request of ``item`` alone, with the reference the next request gets: each
        request takes its reference as it is sent, so polls sent first take this one."""
        why = self.refuses(item.request)
        if why:
            raise LocalProtocolError(why)
        request = self._request([RecordItem(item.request, item.vtype)], self._reference)
        note = (
            f"request reference {self._reference} (the first byte) is the next one; each"
            " request takes its own as it is sent (1-255, round), so a request sent"
            " before this one takes it"
        )
        return Preview(request.encode(), note)

    def _request(self, records: Sequence[RecordItem], reference: int) -> ParameterRequest:
        return record_request(
            records, reference=reference, axis=self.axis, dialect=self.dialect.name
        )

    def transaction(
        self, items: Sequence[Item], *, retries: int, deadline: float, stale: bytes | None = None
    ) -> BatchTransaction:
        reference = self._reference
        self._reference = reference % 255 + 1
        records = [RecordItem(item.request, item.vtype) for item in items]
        request = self._request(records, reference)

        def decode(data: bytes) -> list[Outcome]:
            return self._outcomes(records, request, data)

        return BatchTransaction(
            len(records), request.encode(), decode, retries=retries, deadline=deadline
        )

    def _outcomes(
        self, items: Sequence[RecordItem], request: ParameterRequest, data: bytes
    ) -> list[Outcome]:
        response = profidrive.decode_response(data, request)
        return [self._outcome(item, got) for item, got in zip(items, response.results, strict=True)]

    def _outcome(self, item: RecordItem, got: profidrive.Result) -> Outcome:
        request = item.request
        dialect = self.dialect
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
            # A value wider than a double word (a TimeOfDay or TimeDifference with date: six
            # bytes, ms then days) keeps all its bytes.
            raw = value & ((1 << max(width.value, 8 * got.format.size)) - 1)
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
