"""Parameter catalogs as data: pydantic models and the YAML loader.

A catalog tells, per parameter number (PNU), what the drive's manual says about
it: name, value type, scaling (Danfoss conversion index or a plain factor),
unit, limits, whether the API may write it by default, array length, and where
the fact comes from. See docs/catalogs.md for the file format.

Raises :class:`CatalogError` for a catalog that cannot be found, read or validated.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, StrictInt, ValidationError, model_validator

from pkwbus.errors import PkwbusError
from pkwbus.notation.problems import plain
from pkwbus.notation.yamlfile import YamlError, load_yaml
from pkwbus.protocol.values import types as value_types
from pkwbus.protocol.values.notation import MAX_PNU, ParameterRef, parse_parameter
from pkwbus.protocol.values.types import CONVERSION_FACTORS, Scaling

__all__ = [
    "CONVERSION_INDEXES",
    "Catalog",
    "CatalogError",
    "Dialect",
    "ParameterSpec",
    "ValueType",
    "available_catalogs",
    "load_catalog",
    "load_catalog_file",
]

ValueType = Literal["u16", "i16", "u32", "i32", "f32", "text"]
Dialect = Literal["fc", "uss", "profidrive", "danfoss-pcv", "hitachi-sjpb"]

#: Danfoss conversion indexes (the protocol's table of their factors).
CONVERSION_INDEXES: frozenset[int] = frozenset(CONVERSION_FACTORS)

_DATA_PACKAGE = "pkwbus.catalog"
_DATA_DIR = "data"
_SUFFIX = ".yaml"


class CatalogError(PkwbusError):
    """A catalog cannot be found, read or validated; the message names the place."""


class ParameterSpec(BaseModel):
    """What a catalog knows about one parameter: an entry of a catalog file, validated.

    The configuration applies its overrides to it (:meth:`overridden`); past
    that, the code knows a parameter by its
    :class:`~pkwbus.catalog.description.ParameterDescription` (``from_spec``).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    pnu: int = Field(ge=0, le=MAX_PNU)
    name: str = Field(min_length=1)
    type: ValueType | None = None
    conversion: int | None = None
    scale: float | None = None
    unit: str = ""
    min: float | None = None
    max: float | None = None
    writable: bool = False
    array: int | None = Field(default=None, ge=1)
    # A counter the drive keeps of its own life (operating hours, energy, power-ups):
    # polled by default, slowly (``counters: auto``), each element of an array.
    counter: bool = False
    # A setting of the drive (a value people set: ramps, limits, motor data), swept,
    # compared with its baseline, backed up and restored (``settings: {parameters:
    # catalog}``). None: settings are the entries marked ``writable`` and, in a Siemens
    # catalog, the settable ``p`` parameters.
    setting: bool | None = None
    verified: bool = True
    note: str = ""
    source: str = ""
    # An enumeration's options as a named document words them (number -> text); a
    # number not listed is shown as its number alone. ``options_source`` names it.
    options: dict[StrictInt, str] = Field(default_factory=dict)
    options_source: str = ""
    # The unit of each element of an array whose elements count in different units
    # (SINAMICS r2114 System runtime: [0] ms, [1] days), where ``unit`` can give none. It
    # tells how a counter's value is read out (the status page's text); the value's unit
    # in the API and /metrics stays ``unit``.
    element_units: dict[StrictInt, str] = Field(default_factory=dict)
    # Siemens r (read-only) or p (settable), from the key ("r0021"); empty otherwise.
    prefix: Literal["", "r", "p"] = ""

    @model_validator(mode="after")
    def _check(self) -> Self:
        _check_scaling(self)
        _check_limits(self)
        _check_options(self)
        _check_element_units(self)
        if not self.verified and not self.note.strip():
            raise ValueError("verified: false needs a note saying what could not be sourced")
        return self

    @property
    def is_setting(self) -> bool:
        """Whether the settings sweep reads it (``setting``, else writable or ``p``)."""
        if self.setting is not None:
            return self.setting
        return self.writable or self.prefix == "p"

    def overridden(self, changes: Mapping[str, Any]) -> ParameterSpec:
        """A copy with `changes` (config overrides) applied and validated again.

        Giving `scale` drops the catalog's `conversion` and vice versa, since
        the two are exclusive; making it a text parameter drops both. `pnu`
        cannot change. Raises ValueError naming the field.
        """
        if "pnu" in changes:
            raise ValueError("pnu cannot be overridden")
        fields = self.model_dump()
        if "scale" in changes or changes.get("type") == "text":
            fields["conversion"] = None
        if "conversion" in changes or changes.get("type") == "text":
            fields["scale"] = None
        if {"type", "scale", "conversion"} & changes.keys():
            # The catalog's options number the raw value of its type, and its element
            # units are those of its scaling: another type or a scaling reads the value
            # another way, so they no longer apply.
            fields["options"], fields["options_source"] = {}, ""
            fields["element_units"] = {}
        try:
            return ParameterSpec.model_validate({**fields, **changes})
        except ValidationError as exc:
            raise ValueError(_format_errors("override", "", exc)) from None


def _check_scaling(spec: ParameterSpec) -> None:
    if spec.conversion is not None:
        Scaling.conversion(spec.conversion)  # a LocalProtocolError (ValueError) naming them
    if spec.conversion is not None and spec.scale is not None:
        raise ValueError("give either conversion or scale, not both")
    if spec.scale is not None and (spec.scale == 0 or not math.isfinite(spec.scale)):
        raise ValueError(f"scale must be a finite number other than 0, not {spec.scale}")
    if spec.type == "text" and (spec.conversion is not None or spec.scale is not None):
        raise ValueError("a text parameter has no conversion or scale")


def _check_limits(spec: ParameterSpec) -> None:
    if spec.min is not None and spec.max is not None and spec.min > spec.max:
        raise ValueError(f"min {spec.min} is greater than max {spec.max}")


def _check_options(spec: ParameterSpec) -> None:
    if not spec.options:
        if spec.options_source:
            raise ValueError("options_source without options")
        return
    if not spec.options_source:
        raise ValueError("options need an options_source: the document that words them")
    vtype = value_types.ValueType(spec.type) if spec.type else None
    if vtype is None or not vtype.whole:
        raise ValueError(f"options need a whole-number type (u16, i16, u32, i32), not {spec.type}")
    if spec.conversion not in (None, 0) or spec.scale not in (None, 1):
        raise ValueError("options number the raw value: no conversion or scale")
    low, high = vtype.bounds
    for number, text in spec.options.items():
        if not low <= number <= high:
            raise ValueError(f"option {number} is outside {spec.type} ({low} to {high})")
        if not text.strip():
            raise ValueError(f"option {number} has no text")


def _check_element_units(spec: ParameterSpec) -> None:
    if not spec.element_units:
        return
    if spec.array is None:
        raise ValueError("element_units need an array")
    if spec.unit:
        raise ValueError("give either unit (all elements) or element_units, not both")
    for index, unit in spec.element_units.items():
        if not 0 <= index < spec.array:
            raise ValueError(f"element {index} is outside the array (0 to {spec.array - 1})")
        if not unit.strip():
            raise ValueError(f"element {index} has no unit")


class Catalog(BaseModel):
    """A named set of parameter specs for one kind of drive, keyed by PNU."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1)
    dialect: Dialect
    description: str = ""
    sources: dict[str, str] = Field(default_factory=dict)
    parameters: dict[int, ParameterSpec] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check(self) -> Self:
        for pnu, spec in self.parameters.items():
            if pnu != spec.pnu:
                raise ValueError(f"parameters.{pnu}: key and pnu {spec.pnu} differ")
            for field_name in ("source", "options_source"):
                problem = _source_problem(getattr(spec, field_name), self.sources)
                if problem:
                    raise ValueError(f"parameters.{pnu}.{field_name}: {problem}")
        return self

    def get(self, pnu: int) -> ParameterSpec | None:
        """The spec of parameter `pnu`, or None when the catalog lacks it."""
        return self.parameters.get(pnu)


def _source_problem(source: str, sources: Mapping[str, str]) -> str | None:
    if source and source not in sources:
        known = ", ".join(sorted(sources)) or "none"
        return f"{source!r} is not in the sources table (known: {known})"
    return None


# --- parameter keys ---------------------------------------------------------


def _key_ref(text: str) -> ParameterRef:
    """A catalog key in the notation everything else uses: "16-13", "1613", "r0021"."""
    if "[" in text:
        raise ValueError(f"{text!r}: a catalog key names a parameter, not an index")
    return parse_parameter(text)  # ParameterNotationError is a ValueError


def _parse_key(text: str) -> int:
    """PNU of a catalog key: "16-13" -> 1613, "1613" -> 1613, "r0021"/"p1082" -> 21/1082."""
    return _key_ref(text).pnu


# --- YAML -------------------------------------------------------------------


def _read_yaml(text: str, origin: str) -> dict[str, Any]:
    try:
        data = load_yaml(text)
    except YamlError as exc:
        raise CatalogError(f"{origin}: {exc}") from None
    if not isinstance(data, dict):
        raise CatalogError(f"{origin}: the file must be a mapping with name, dialect, parameters")
    return data


# --- validation with readable errors ----------------------------------------


def _format_errors(origin: str, place: str, exc: ValidationError) -> str:
    """One line per problem: `FILE: place.field: message` (place may be empty)."""
    lines = []
    for error in exc.errors():
        parts = [place] if place else []
        path = ".".join(parts + [str(part) for part in error["loc"]])
        message = plain(error)
        lines.append(f"{origin}: {path}: {message}" if path else f"{origin}: {message}")
    return "\n".join(lines)


def _key_text(key: object) -> str:
    if isinstance(key, int) and not isinstance(key, bool):
        return str(key)
    if isinstance(key, str):
        return key
    return repr(key)


def _parse_entry(key: object, entry: object, origin: str) -> ParameterSpec:
    place = f'parameters."{_key_text(key)}"'
    where = f"{origin}: {place}"
    try:
        ref = _key_ref(_key_text(key))
    except ValueError as exc:
        raise CatalogError(f"{where}: {exc}") from None
    if not isinstance(entry, dict):
        raise CatalogError(f"{where}: expected a mapping of fields (name, type, ...)")
    for derived in ("pnu", "prefix"):
        if derived in entry:
            raise CatalogError(f"{where}.{derived}: it comes from the key; remove this field")
    try:
        return ParameterSpec.model_validate({**entry, "pnu": ref.pnu, "prefix": ref.prefix})
    except ValidationError as exc:
        raise CatalogError(_format_errors(origin, place, exc)) from None


def _parse_parameters(data: Mapping[str, Any], origin: str) -> dict[int, ParameterSpec]:
    raw = data.get("parameters") or {}
    if not isinstance(raw, dict):
        raise CatalogError(f"{origin}: parameters: expected a mapping keyed by parameter")
    sources = data.get("sources")
    sources = sources if isinstance(sources, dict) else {}
    specs: dict[int, ParameterSpec] = {}
    first_key: dict[int, str] = {}
    for key, entry in raw.items():
        spec = _parse_entry(key, entry, origin)
        where = f'{origin}: parameters."{_key_text(key)}"'
        if spec.pnu in specs:
            raise CatalogError(
                f'{where}: PNU {spec.pnu} is already defined as "{first_key[spec.pnu]}"'
            )
        for field_name in ("source", "options_source"):
            problem = _source_problem(getattr(spec, field_name), sources)
            if problem:
                raise CatalogError(f"{where}.{field_name}: {problem}")
        specs[spec.pnu] = spec
        first_key[spec.pnu] = _key_text(key)
    return specs


def _parse_catalog(text: str, origin: str) -> Catalog:
    data = _read_yaml(text, origin)
    parameters = _parse_parameters(data, origin)
    header = {key: value for key, value in data.items() if key != "parameters"}
    try:
        return Catalog.model_validate({**header, "parameters": parameters})
    except ValidationError as exc:
        raise CatalogError(_format_errors(origin, "", exc)) from None


# --- public entry points ----------------------------------------------------


def _data_dir() -> Any:
    return resources.files(_DATA_PACKAGE).joinpath(_DATA_DIR)


def available_catalogs() -> list[str]:
    """Names of the catalogs shipped with pkwbus, sorted."""
    names = (
        entry.name.removesuffix(_SUFFIX)
        for entry in _data_dir().iterdir()
        if entry.name.endswith(_SUFFIX)
    )
    return sorted(names)


@functools.cache
def load_catalog(name: str) -> Catalog:
    """A built-in catalog by name (e.g. "danfoss-fc"); loaded once, then cached."""
    known = available_catalogs()
    if name not in known:
        raise CatalogError(f"unknown catalog {name!r}; available: {', '.join(known)}")
    filename = f"{name}{_SUFFIX}"
    catalog = _parse_catalog(_data_dir().joinpath(filename).read_text("utf-8"), filename)
    if catalog.name != name:
        raise CatalogError(f"{filename}: name: {catalog.name!r} differs from the file name")
    return catalog


def load_catalog_file(path: str | os.PathLike[str]) -> Catalog:
    """A catalog from a YAML file of the same format as the built-in ones."""
    try:
        text = Path(path).read_text("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise CatalogError(f"{os.fspath(path)}: cannot read: {reason}") from None
    return _parse_catalog(text, os.fspath(path))
