"""One parameter as the code past the catalog files sees it: :class:`ParameterDescription`.

The one description of a parameter: its name, value type, scaling, unit,
limits, array length, whether a write is allowed, and its Siemens r/p. The
catalog's :class:`~pkwbus.catalog.ParameterSpec` (an entry of a catalog file,
with the config's overrides applied) becomes one through
:meth:`ParameterDescription.from_spec`; the service resolves one per parameter
of each drive when it is built (a :class:`ParameterTable`), and the master
decodes and encodes values with it. Pure: no I/O, no clock.

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a value that
cannot be written (:meth:`ParameterDescription.encode`) and
:class:`~pkwbus.protocol.errors.RemoteProtocolError` for an answer that
carries no value (:meth:`ParameterDescription.value_of`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import TYPE_CHECKING, Final

from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.values import (
    UNSCALED,
    ParameterRef,
    Scaling,
    ValueType,
    canonical,
    decode_text,
    decode_value,
    encode_exact,
)

if TYPE_CHECKING:
    from pkwbus.catalog.loader import ParameterSpec

__all__ = [
    "OTHER_INDEX",
    "ParameterDescription",
    "ParameterKey",
    "ParameterTable",
    "Value",
    "name_for_unit",
]

Value = int | float | str
_NO_OPTIONS: Final[Mapping[int, str]] = MappingProxyType({})


def _no_options() -> Mapping[int, str]:
    return _NO_OPTIONS


_UNIT_IN_NAME = re.compile(r"^(.*?)\s*\[([^\[\]]*)\]$")


def name_for_unit(name: str, unit: str) -> str:
    """``name`` without the unit in brackets at its end where that is not ``unit``."""
    found = _UNIT_IN_NAME.match(name)
    if found is None or found.group(2).strip().casefold() == unit.strip().casefold():
        return name
    return found.group(1)


@dataclass(frozen=True, slots=True)
class ParameterDescription:
    """Type, scaling, unit, limits and writability of one parameter (all optional).

    ``name`` is the catalog's (or the configuration's) name, empty when neither
    knows the parameter; its value is then read and shown raw. ``writable`` is
    the catalog's default outside the service; in the service's tables it is
    whether the drive's ``writable`` list allows the write.
    """

    name: str = ""
    vtype: ValueType | None = None
    scaling: Scaling = UNSCALED
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    array: int | None = None  # number of elements, when the catalog says it is an array
    writable: bool = False
    prefix: str = ""  # Siemens r (read-only) or p (settable), when the catalog says
    # An enumeration's options (number -> the catalog's sourced text); empty for none.
    options: Mapping[int, str] = field(default_factory=_no_options, hash=False)
    counter: bool = False  # a counter the drive keeps of its own life (catalog ``counter``)
    # The unit of each element where an array's elements count in different units
    # (catalog ``element_units``: r2114 [0] ms, [1] d), and the one of the element
    # described (:meth:`at`). They tell how the value reads out (``readable``); ``unit``,
    # the unit the API and /metrics give the value, stays as it is.
    element_units: Mapping[int, str] = field(default_factory=_no_options, hash=False)
    element_unit: str = ""

    def __post_init__(self) -> None:
        # A unit in the name ("Power [kW]", as the vendor names 16-10) that is not the unit
        # the value is shown in (W, the base unit its conversion index scales to) would
        # contradict the value beside it: the name is shown without it.
        object.__setattr__(self, "name", name_for_unit(self.name, self.unit))

    @classmethod
    def from_spec(cls, spec: ParameterSpec | None) -> ParameterDescription:
        """The description of a catalog entry; an empty one (raw values) for None."""
        if spec is None:
            return cls()
        if spec.conversion is not None:
            scaling = Scaling.conversion(spec.conversion)
        elif spec.scale is not None:
            scaling = Scaling.scale(spec.scale)
        else:
            scaling = UNSCALED
        vtype = ValueType(spec.type) if spec.type else None
        return cls(
            spec.name,
            vtype,
            scaling,
            spec.unit,
            spec.min,
            spec.max,
            spec.array,
            spec.writable,
            spec.prefix,
            MappingProxyType(dict(spec.options)) if spec.options else _NO_OPTIONS,
            counter=spec.counter,
            element_units=(
                MappingProxyType(dict(spec.element_units)) if spec.element_units else _NO_OPTIONS
            ),
        )

    def at(self, index: int | None) -> ParameterDescription:
        """The description of element ``index`` (None: the parameter as a whole): with the
        element's own unit where the catalog gives its elements different units."""
        if not self.element_units:
            return self
        unit = self.element_units.get(index, "") if index is not None else ""
        return self if unit == self.element_unit else replace(self, element_unit=unit)

    def with_type(self, vtype: ValueType | None) -> ParameterDescription:
        """The same with the value type ``vtype`` (from the command line, say), if given."""
        if vtype is None:
            return self
        return replace(self, vtype=vtype)

    @property
    def is_text(self) -> bool:
        return self.vtype is ValueType.TEXT

    @property
    def enumerates(self) -> bool:
        """Options that apply: they number the raw value, so the value must be a whole
        number, unscaled (a drive that describes it scaled reads its own way)."""
        whole = self.vtype is not None and self.vtype.whole
        return bool(self.options) and whole and self.scaling == UNSCALED

    def option(self, value: Value) -> str:
        """The enumeration's text for ``value``; empty where the catalog words none."""
        if self.enumerates and isinstance(value, int) and not isinstance(value, bool):
            return self.options.get(value, "")
        return ""

    def value_of(self, response: pkw.PkwResponse) -> tuple[int | None, Value]:
        """(raw number, value) of an answer; the peer's error when it does not carry one."""
        if isinstance(response, pkw.TextResponse):
            return None, decode_text(response.text)
        if isinstance(response, pkw.ValueResponse):
            # The type the answer names itself comes first: a float is a float.
            vtype = response.vtype or (None if self.vtype is ValueType.TEXT else self.vtype)
            return response.raw, decode_value(response.raw, response.width, vtype, self.scaling)
        raise RemoteProtocolError(f"answer {type(response).__name__} carries no value")

    def encode(self, value: Value, parameter: str = "") -> tuple[int, pkw.Width]:
        """The raw number and width for writing ``value``; nothing is sent on an error.

        The one rule for writes, from the command line and the API: within the
        limits and held exactly (:func:`~pkwbus.protocol.values.encode_exact`),
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


#: The key, in :attr:`ParameterTable.configured`, of an index the configuration does not name.
OTHER_INDEX: Final = -1

ParameterKey = tuple[int, int | None]
_UNKNOWN = ParameterDescription()


def _empty() -> Mapping[ParameterKey, ParameterDescription]:
    return MappingProxyType({})


def _empty_catalog() -> Mapping[int, ParameterDescription]:
    return MappingProxyType({})


@dataclass(frozen=True)
class ParameterTable:
    """Every parameter of one drive, resolved once: PNU (and index) -> its description.

    ``configured``: the parameters the configuration names, the catalog entry
    with the configuration's overrides, writable when the drive's ``writable``
    list allows it; keyed by (PNU, index), (PNU, None) for no index and
    (PNU, :data:`OTHER_INDEX`) for an index the configuration does not name,
    when that differs from (PNU, None). ``catalog``: the entries of the drive's
    catalog as they are, none writable. A parameter in neither is unknown: its
    value is read and shown raw. Immutable: the tables are read-only mappings.
    """

    danfoss: bool = False  # the drive numbers its parameters in groups (Danfoss FC)
    configured: Mapping[ParameterKey, ParameterDescription] = field(default_factory=_empty)
    catalog: Mapping[int, ParameterDescription] = field(default_factory=_empty_catalog)

    def describe(self, ref: ParameterRef) -> ParameterDescription:
        """What is known of ``ref`` (with its index, :meth:`ParameterDescription.at`) on the
        drive."""
        keys: tuple[ParameterKey, ...] = ((ref.pnu, ref.index),)
        if ref.index is not None:
            keys += ((ref.pnu, OTHER_INDEX), (ref.pnu, None))
        for key in keys:
            found = self.configured.get(key)
            if found is not None:
                return found.at(ref.index)
        return self.catalog.get(ref.pnu, _UNKNOWN).at(ref.index)

    def canonical(self, ref: ParameterRef) -> ParameterRef:
        """``ref`` under the drive's one name for it (``3-41`` for ``341`` on an FC drive,
        ``r0021`` when the catalog or configuration gives the prefix); a
        :class:`~pkwbus.protocol.values.ParameterNotationError` for r/p on an FC drive."""
        prefix = self.describe(ParameterRef(ref.pnu, None, ref.name)).prefix
        return canonical(ref, danfoss=self.danfoss, prefix=prefix)
