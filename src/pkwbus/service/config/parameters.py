"""What the configuration says about a parameter: its overrides of the catalog, its polling."""

from __future__ import annotations

from typing import Any, Final, Self

from pydantic import (
    Field,
    StrictInt,
    field_validator,
    model_validator,
)

from pkwbus.protocol.values import (
    MAX_INDEX,
    ParameterRef,
    Scaling,
)
from pkwbus.service.config.base import Model, Place, fail
from pkwbus.service.config.fields import Interval, Notation, Number, TypeName

__all__ = ["OVERRIDE_FIELDS", "ParameterOverrides", "Poll", "ref_key"]


class ParameterOverrides(Model):
    """What the config says about a parameter, over its catalog entry."""

    type: TypeName | None = None
    scale: Number | None = None
    conversion: StrictInt | None = None
    unit: str | None = Field(default=None, strict=True)
    min: Number | None = None
    max: Number | None = None
    name: str | None = Field(default=None, strict=True, min_length=1)

    @field_validator("scale")
    @classmethod
    def _scale_not_zero(cls, value: float | None) -> float | None:
        if value == 0:
            raise ValueError("0 is not a scale: it would make every value 0")
        return value

    @field_validator("conversion")
    @classmethod
    def _known_conversion(cls, value: int | None) -> int | None:
        if value is not None:
            Scaling.conversion(value)
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        problems: list[Place] = []
        if self.scale is not None and self.conversion is not None:
            problems.append(("conversion", "give scale or conversion, not both"))
        if self.min is not None and self.max is not None and self.min > self.max:
            problems.append(("min", f"{self.min} is above max {self.max}"))
        if problems:
            raise fail(problems)
        return self

    @property
    def scaling(self) -> Scaling | None:
        """The configured scaling, None when the config leaves it to the catalog."""
        if self.conversion is not None:
            return Scaling.conversion(self.conversion)
        if self.scale is not None:
            return Scaling.scale(self.scale)
        return None

    def given(self) -> bool:
        """Whether any override is set."""
        return any(getattr(self, key) is not None for key in OVERRIDE_FIELDS)

    def changes(self) -> dict[str, Any]:
        """The overrides that are set, as :meth:`ParameterSpec.overridden` takes them."""
        values = {key: getattr(self, key) for key in OVERRIDE_FIELDS}
        if self.type is not None:
            values["type"] = self.type.value
        return {key: value for key, value in values.items() if value is not None}

    def overrides(self) -> ParameterOverrides:
        """Only the override fields (of a poll entry, say)."""
        values = {key: getattr(self, key) for key in OVERRIDE_FIELDS}
        return ParameterOverrides.model_construct(**values)


OVERRIDE_FIELDS: Final = ("type", "scale", "conversion", "unit", "min", "max", "name")


class Poll(ParameterOverrides):
    """One polled parameter: ``{parameter: "16-13", every: 1s}`` plus optional overrides."""

    parameter: Notation
    every: Interval
    index: StrictInt | None = Field(default=None, ge=0, le=MAX_INDEX)

    @model_validator(mode="after")
    def _index_once(self) -> Self:
        if self.index is not None and self.parameter.index is not None:
            raise fail([("index", f"the index is already in {self.parameter}: give it once")])
        return self

    @property
    def ref(self) -> ParameterRef:
        """The parameter with its index, from the notation or from ``index``."""
        if self.index is None:
            return self.parameter
        return ParameterRef(self.parameter.pnu, self.index, self.parameter.name)


def ref_key(ref: ParameterRef) -> tuple[int, int | None]:
    return (ref.pnu, ref.index)
