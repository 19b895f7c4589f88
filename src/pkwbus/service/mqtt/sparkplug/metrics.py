"""The metrics of the Sparkplug edge node and its devices (the drives), from the catalog:
each with a name, an alias unique across the node, a datatype and a unit.

A drive's metrics are its polled values, then the parameters its ``writable`` list names
that are not polled (a host application writes only what a birth announced). A metric
is named as the parameter is on the drive (``16-13``, ``r0021``), an index other than 0
as a folder below it (``r0947/3``). Its datatype follows the catalog: text a String, a
scaled number a Double (a Float for a 32-bit float), a whole number of its width and
sign (UInt16, Int16, UInt32, Int32), an untyped one a Double. Its unit is the metric's
``engUnit`` property: the specification defines no key for units, and ``engUnit`` is the
one Ignition's tags carry.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

from pkwbus.catalog.description import OTHER_INDEX, ParameterDescription, Value
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.values import ParameterRef, parse_parameter
from pkwbus.protocol.values.types import ValueType
from pkwbus.service.mqtt.sparkplug.codec import DataType, MetricValue
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = [
    "BD_SEQ",
    "BD_SEQ_ALIAS",
    "FIRST_DEVICE_ALIAS",
    "REBIRTH",
    "REBIRTH_ALIAS",
    "DeviceMetric",
    "datatype_of",
    "device_metrics",
    "metric_value",
]

BD_SEQ = "bdSeq"
REBIRTH = "Node Control/Rebirth"
BD_SEQ_ALIAS, REBIRTH_ALIAS = 0, 1  # the node's own metrics
FIRST_DEVICE_ALIAS = 2

_WHOLE = {
    ValueType.U16: DataType.UINT16,
    ValueType.I16: DataType.INT16,
    ValueType.U32: DataType.UINT32,
    ValueType.I32: DataType.INT32,
}


@dataclass(frozen=True, slots=True)
class DeviceMetric:
    """One metric of a drive: ``reading`` the snapshot's key of its polled value (None: a
    writable parameter not polled); ``parameter`` and ``index`` what a write names."""

    drive: str
    name: str
    alias: int
    datatype: DataType
    unit: str
    parameter: str
    index: int | None
    pnu: int
    reading: ReadingKey | None


def datatype_of(fmt: ParameterDescription) -> DataType:
    if fmt.is_text or fmt.vtype is ValueType.TEXT:
        return DataType.STRING
    if fmt.vtype is ValueType.F32:
        return DataType.FLOAT
    if fmt.vtype is None or fmt.scaling.factor != 1:
        return DataType.DOUBLE
    return _WHOLE[fmt.vtype]


def metric_value(datatype: DataType, value: Value | None) -> MetricValue | None:
    """``value`` as a metric of ``datatype`` carries it; None (is_null) for what it
    cannot (a number where text belongs, a fraction in a whole number, not finite)."""
    if value is None:
        return None
    if datatype is DataType.STRING:
        return value if isinstance(value, str) else None
    if isinstance(value, str):
        return None
    if datatype in (DataType.DOUBLE, DataType.FLOAT):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, float):
        return int(value) if value.is_integer() else None
    return value


def _name(parameter: str, index: int | None) -> str:
    return parameter if not index else f"{parameter}/{index}"


def _writable(entry: DriveEntry) -> Iterator[tuple[ParameterRef, ParameterDescription]]:
    """The parameters the drive's ``writable`` list names, by the drive's name for them."""
    for (pnu, index), fmt in entry.parameters.configured.items():
        if not fmt.writable or index == OTHER_INDEX:
            continue
        try:
            ref = entry.canonical(parse_parameter(str(pnu)))
        except LocalProtocolError:
            continue
        yield ParameterRef(ref.pnu, index, ref.name), fmt


def device_metrics(runtime: Runtime, first_alias: int = FIRST_DEVICE_ALIAS) -> list[DeviceMetric]:
    """Every drive's metrics, drives by name, aliases from ``first_alias`` on."""
    found: list[DeviceMetric] = []
    alias = first_alias
    for name in sorted(runtime.drives):
        entry = runtime.drives[name]
        seen: set[tuple[int, int]] = set()
        for poll in entry.polls:
            pnu = poll.request.pnu
            if (pnu, poll.index) in seen:
                continue
            seen.add((pnu, poll.index))
            fmt = poll.fmt
            found.append(
                DeviceMetric(
                    name,
                    _name(poll.parameter, poll.index),
                    alias,
                    datatype_of(fmt),
                    fmt.unit,
                    poll.parameter,
                    poll.index or None,
                    pnu,
                    (name, poll.parameter, poll.index),
                )
            )
            alias += 1
        for ref, fmt in _writable(entry):
            if (ref.pnu, ref.index or 0) in seen:
                continue
            seen.add((ref.pnu, ref.index or 0))
            found.append(
                DeviceMetric(
                    name,
                    _name(ref.name, ref.index),
                    alias,
                    datatype_of(fmt),
                    fmt.unit,
                    ref.name,
                    ref.index,
                    ref.pnu,
                    None,
                )
            )
            alias += 1
    return found
