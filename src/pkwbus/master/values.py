"""How a parameter's raw PWE becomes a value and back: type, scaling, unit, limits."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.params import (
    UNSCALED,
    Scaling,
    ValueType,
    decode_text,
    decode_value,
    encode_exact,
)

Value = int | float | str


class SpecLike(Protocol):
    """What a catalog entry or a configuration override says about a parameter."""

    @property
    def name(self) -> str: ...
    @property
    def type(self) -> str | None: ...
    @property
    def conversion(self) -> int | None: ...
    @property
    def scale(self) -> float | None: ...
    @property
    def unit(self) -> str: ...
    @property
    def array(self) -> int | None: ...
    @property
    def min(self) -> float | None: ...
    @property
    def max(self) -> float | None: ...


@dataclass(frozen=True, slots=True)
class ParameterFormat:
    """Type, scaling, unit and limits of one parameter (all optional)."""

    name: str = ""
    vtype: ValueType | None = None
    scaling: Scaling = UNSCALED
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    array: int | None = None  # number of elements, when the catalog says it is an array

    @classmethod
    def from_spec(cls, spec: SpecLike | None) -> ParameterFormat:
        if spec is None:
            return cls()
        if spec.conversion is not None:
            scaling = Scaling.conversion(spec.conversion)
        elif spec.scale is not None:
            scaling = Scaling.scale(spec.scale)
        else:
            scaling = UNSCALED
        vtype = ValueType(spec.type) if spec.type else None
        return cls(spec.name, vtype, scaling, spec.unit, spec.min, spec.max, spec.array)

    def with_type(self, vtype: ValueType | None) -> ParameterFormat:
        if vtype is None:
            return self
        return ParameterFormat(
            self.name, vtype, self.scaling, self.unit, self.minimum, self.maximum, self.array
        )

    @property
    def is_text(self) -> bool:
        return self.vtype is ValueType.TEXT

    def value_of(self, response: pkw.PkwResponse) -> tuple[int | None, Value]:
        """(raw number, value) of an answer; the peer's error when it does not carry one."""
        if isinstance(response, pkw.TextResponse):
            return None, decode_text(response.text)
        if isinstance(response, pkw.ValueResponse):
            vtype = None if self.vtype is ValueType.TEXT else self.vtype
            return response.raw, decode_value(response.raw, response.width, vtype, self.scaling)
        raise RemoteProtocolError(f"answer {type(response).__name__} carries no value")

    def encode(self, value: Value, parameter: str = "") -> tuple[int, pkw.Width]:
        """The raw number and width for writing ``value``; nothing is sent on an error.

        The one rule for writes, from the command line and the API: within the
        limits and held exactly (:func:`~pkwbus.protocol.params.encode_exact`),
        never rounded; the error names ``parameter`` and the nearest values.
        """
        if self.vtype is None:
            raise LocalProtocolError("the parameter's type is not known: give it a type")
        if self.vtype is ValueType.TEXT:
            raise LocalProtocolError("text parameters cannot be written as a number")
        raw = encode_exact(
            value,
            self.vtype,
            self.scaling,
            parameter=parameter,
            minimum=self.minimum,
            maximum=self.maximum,
            unit=self.unit,
        )
        width = self.vtype.width
        assert width is not None
        return raw, width
