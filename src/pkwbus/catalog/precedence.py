"""Which description of a parameter counts: the configuration's, then the drive's, then the
catalog's, field by field; and where the drive and the catalog disagree.

What the configuration sets explicitly (``type``, ``scale`` or ``conversion``,
``unit``, ``min``, ``max``, ``name``) comes first; then what the drive
describes of itself (its description elements,
:class:`~pkwbus.protocol.pkw.descriptions.DriveDescription`); then the catalog.
A drive that described nothing leaves today's description (configuration over
catalog) as it is. A drive's name that the catalog's name begins with is the
catalog's cut to the drive's 16 characters: the whole name is shown. Pure: no
I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Final

from pkwbus.catalog.description import ParameterDescription
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.values.types import Scaling

__all__ = ["SOURCES", "Disagreement", "Layers", "Resolved", "disagreements", "resolve"]

#: Where a parameter's description came from (the ``source`` label): its scaling and type.
SOURCES: Final = ("config", "drive", "catalog", "none")


@dataclass(frozen=True, slots=True)
class Layers:
    """What the configuration sets explicitly of one parameter, and its catalog entry.

    ``config`` holds only the fields the configuration gives (the others at
    their defaults); ``given`` names them: ``type``, ``scaling``, ``unit``,
    ``min``, ``max``, ``name``. ``merged`` is the configuration over the
    catalog: the description while the drive has said nothing.
    """

    merged: ParameterDescription
    config: ParameterDescription = field(default_factory=ParameterDescription)
    given: frozenset[str] = frozenset()
    catalog: ParameterDescription | None = None


@dataclass(frozen=True, slots=True)
class Disagreement:
    """A field on which the drive and the catalog differ, both values as text."""

    field: str
    drive: str
    catalog: str


@dataclass(frozen=True, slots=True)
class Resolved:
    description: ParameterDescription
    source: str  # one of SOURCES: where its scaling and type came from


def resolve(layers: Layers, drive: DriveDescription | None) -> Resolved:
    """The description that counts, given what the drive said (None: nothing)."""
    merged, given, catalog = layers.merged, layers.given, layers.catalog
    config = layers.config
    if drive is None or drive.empty:
        return Resolved(merged, _source(given, False, catalog))
    vtype = config.vtype if "type" in given else (drive.vtype or merged.vtype)
    scaling = config.scaling if "scaling" in given else (drive.scaling or merged.scaling)
    unit = config.unit if "unit" in given else _unit(drive, merged)
    # The drive's limits are raw numbers as it sends them: scaled as its values are.
    low = config.minimum if "min" in given else _first(_scaled(drive.low_raw, scaling),
                                                       merged.minimum)  # fmt: skip
    high = config.maximum if "max" in given else _first(_scaled(drive.high_raw, scaling),
                                                        merged.maximum)  # fmt: skip
    name = config.name if "name" in given else _name(drive.name, merged.name)
    array = drive.array if drive.array is not None else merged.array
    described = drive.vtype is not None or drive.scaling is not None
    resolved = replace(
        merged, name=name, vtype=vtype, scaling=scaling, unit=unit, minimum=low, maximum=high,
        array=array,
    )  # fmt: skip
    if scaling != merged.scaling and merged.element_units:
        # The catalog's element units are those of its scaling, as its unit is (_unit).
        resolved = replace(resolved, element_units=ParameterDescription().element_units,
                           element_unit="")  # fmt: skip
    return Resolved(resolved, _source(given, described, catalog))


def disagreements(drive: DriveDescription, catalog: ParameterDescription) -> list[Disagreement]:
    """The fields (type, scaling, unit, limits) on which ``drive`` and ``catalog`` differ,
    where both say something."""
    found: list[Disagreement] = []
    if drive.vtype is not None and catalog.vtype is not None and drive.vtype != catalog.vtype:
        found.append(Disagreement("type", drive.vtype.value, catalog.vtype.value))
    scaling = drive.scaling
    if scaling is not None and catalog.vtype is not None and scaling != catalog.scaling:
        found.append(Disagreement("scaling", _factor(scaling), _factor(catalog.scaling)))
    if drive.unit and catalog.unit and drive.unit != catalog.unit:
        found.append(Disagreement("unit", drive.unit, catalog.unit))
    for name, ours, theirs in (
        ("min", drive.minimum, catalog.minimum),
        ("max", drive.maximum, catalog.maximum),
    ):
        if ours is not None and theirs is not None and not _same(ours, theirs):
            found.append(Disagreement(name, f"{ours:g}", f"{theirs:g}"))
    return found


def _source(given: frozenset[str], described: bool, catalog: ParameterDescription | None) -> str:
    if given & {"type", "scaling"}:
        return "config"
    if described:
        return "drive"
    return "catalog" if catalog is not None else "none"


def _name(drive: str, known: str) -> str:
    """The drive's name, unless the catalog's begins with it: a drive names a parameter in
    at most 16 characters (PROFIdrive element 6), where the catalog may give it whole."""
    if drive and not known.casefold().startswith(drive.casefold()):
        return drive
    return known or drive


def _unit(drive: DriveDescription, known: ParameterDescription) -> str:
    """The drive's unit; else the catalog's where the drive's scaling is the catalog's (or
    it gave none); else none: a unit that belongs to another scaling would be wrong."""
    if drive.unit:
        return drive.unit
    if drive.scaling is None or drive.scaling == known.scaling:
        return known.unit
    return ""


def _scaled(raw: int | float | None, scaling: Scaling) -> float | None:
    return None if raw is None else float(raw * scaling.factor)


def _first(a: float | None, b: float | None) -> float | None:
    return a if a is not None else b


def _factor(scaling: Scaling) -> str:
    return f"x{float(scaling.factor):g}"


def _same(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9)
