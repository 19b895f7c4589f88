"""A simulated drive's PROFIdrive parameter access (data record 47): a request in, its
response out, from the drive's parameters.

Each parameter of a request is carried out as the drive's PKW channel would
(:meth:`pkwbus.sim.drives.params.ParameterStore.execute`), so values, limits,
read-only parameters and refusals are the same on both channels; a refusal's
fault number is its PROFIdrive error number (the SINAMICS and Danfoss PKW
fault numbers follow the profile's error numbers). Values go out in the
parameter's format (Unsigned16, Integer32, FloatingPoint...); a text as an
octet string; a description element as the drive's PKW description gives it.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw import Width
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.profidrive import drive as profidrive_drive
from pkwbus.protocol.profidrive import parameters as profidrive
from pkwbus.protocol.profidrive.parameters import (
    Attribute,
    Format,
    ParameterAddress,
    ParameterError,
    RequestId,
    Values,
)
from pkwbus.protocol.profidrive.pkw import FORMATS
from pkwbus.protocol.values.types import ValueType
from pkwbus.sim.drives.params import ParameterStore

__all__ = ["Own", "RecordServer"]

# Parameters a drive answers ahead of its store (a log in types the table has not): one
# parameter's result, None for one it does not hold.
Own = Callable[[ParameterAddress], Values | ParameterError | None]

_ILLEGAL_ADDRESS = 0x16
_NUMBER_OF_VALUES = 0x18
_FORMAT = 0x17
_AXIS = 0x19


class RecordServer:
    """Answers data record 47 requests of one drive, for its axis (DO-ID)."""

    def __init__(
        self, store: ParameterStore, dialect: Dialect, axis: int, own: Own | None = None
    ) -> None:
        self.store = store
        self.dialect = dialect
        self.axis = axis
        self.own = own
        self.requests = 0

    def answer(self, data: bytes) -> bytes:
        """The response to a request record; RemoteProtocolError for one that does not
        decode (the slave then refuses the write)."""
        request = profidrive_drive.decode_request(data)
        self.requests += 1
        results: list[profidrive.Result] = []
        for i, address in enumerate(request.addresses):
            if request.axis != self.axis:
                results.append(ParameterError(_AXIS))
            elif request.request_id is RequestId.READ:
                results.append(self._read(address))
            else:
                results.append(self._change(address, request.changes[i]))
        return profidrive_drive.encode_response(request, results)

    def _read(self, address: ParameterAddress) -> Values | ParameterError:
        if self.own is not None and (result := self.own(address)) is not None:
            return result
        if address.attribute is Attribute.TEXT:
            return ParameterError(self.store.faults.no_text)
        if address.attribute is Attribute.DESCRIPTION:
            request = pkw.read_description(self.dialect, address.pnu, address.subindex)
            response = self.store.execute(request)
            if isinstance(response, pkw.DescriptionResponse):
                if response.data is not None:
                    return Values(Format.OCTET_STRING, (response.data,))
                fmt = Format.U16 if response.width is Width.WORD else Format.U32
                return Values(fmt, (response.raw,))
            return self._error(response)
        values: list[int | float | bytes] = []
        fmt = Format.U16
        for index in range(address.subindex, address.subindex + max(address.elements, 1)):
            indexed = address.elements > 1 or address.subindex > 0
            response = self.store.execute(
                pkw.read(self.dialect, address.pnu, index if indexed else None)
            )
            if isinstance(response, pkw.TextResponse):
                return Values(Format.OCTET_STRING, (response.text,))
            if not isinstance(response, pkw.ValueResponse):
                return self._error(response)
            fmt, value = self._value(address.pnu, response.raw)
            values.append(value)
        return Values(fmt, tuple(values))

    def _value(self, pnu: int, raw: int) -> tuple[Format, int | float]:
        vtype = self.store.specs[pnu].vtype
        fmt = FORMATS.get(vtype, Format.U16)
        if fmt is Format.FLOAT:
            return fmt, float(struct.unpack(">f", raw.to_bytes(4, "big"))[0])
        bits = 16 if vtype.width is Width.WORD else 32
        if fmt in (Format.I16, Format.I32) and raw >= 1 << (bits - 1):
            return fmt, raw - (1 << bits)
        return fmt, raw

    def _change(self, address: ParameterAddress, values: Values) -> ParameterError | None:
        if address.attribute is not Attribute.VALUE:
            return ParameterError(_ILLEGAL_ADDRESS)
        if len(values.values) != max(address.elements, 1):
            return ParameterError(_NUMBER_OF_VALUES)
        spec = self.store.specs.get(address.pnu)
        if spec is None:
            return ParameterError(self.store.faults.illegal_pnu)
        wanted = FORMATS.get(spec.vtype)
        if wanted is None or values.format not in (wanted, _WORDS.get(wanted)):
            return ParameterError(_FORMAT)
        for offset, value in enumerate(values.values):
            index = address.subindex + offset
            indexed = address.elements > 1 or address.subindex > 0
            try:
                substitute = values.format in (Format.WORD, Format.DOUBLE_WORD)
                raw = value if substitute and isinstance(value, int) else _raw(value, spec.vtype)
                width = spec.vtype.width or Width.DWORD
                where = index if indexed else None
                request = pkw.write(self.dialect, address.pnu, raw, width, index=where)
            except (LocalProtocolError, struct.error, OverflowError, TypeError):
                return ParameterError(_FORMAT)
            response = self.store.execute(request)
            if not isinstance(response, pkw.ValueResponse):
                return self._error(response)
        return None

    def _error(self, response: pkw.PkwResponse) -> ParameterError:
        if isinstance(response, pkw.Rejection) and response.fault is not None:
            return ParameterError(response.fault)
        raise RemoteProtocolError(f"no error number in {response}")


_WORDS = {Format.U16: Format.WORD, Format.I16: Format.WORD, Format.U32: Format.DOUBLE_WORD,
          Format.I32: Format.DOUBLE_WORD, Format.FLOAT: Format.DOUBLE_WORD}  # fmt: skip


def _raw(value: int | float | bytes, vtype: ValueType) -> int:
    """The PKW raw value of a record's value (a float's bits, a negative number's two's
    complement)."""
    if isinstance(value, bytes):
        raise TypeError("a text is no number")
    if vtype is ValueType.F32:
        return int.from_bytes(struct.pack(">f", value), "big")
    bits = 16 if vtype.width is Width.WORD else 32
    number = int(value)
    if not -(1 << (bits - 1)) <= number < 1 << bits:
        raise OverflowError(f"{number} does not fit {bits} bits")
    return number & ((1 << bits) - 1)
