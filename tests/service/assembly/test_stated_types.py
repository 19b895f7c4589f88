"""The type a drive names in its own answers types a parameter that nothing else types:
never over the configuration, the drive's description or the catalog."""

from __future__ import annotations

from types import MappingProxyType

from pkwbus.catalog.description import ParameterDescription, ParameterTable
from pkwbus.master.target import DriveTarget
from pkwbus.protocol.values import ParameterRef
from pkwbus.protocol.values.types import ValueType
from pkwbus.service.runtime import DriveEntry

TYPED = ParameterDescription("Ramp-down time", ValueType.F32, unit="s", writable=True)


def entry() -> DriveEntry:
    table = ParameterTable(
        configured=MappingProxyType({(1121, None): TYPED, (1082, None): ParameterDescription()})
    )
    return DriveEntry("pump", "dp", DriveTarget.create("profibus", 9, dialect_name="profidrive"),
                      parameters=table)  # fmt: skip


def test_a_stated_type_only_where_nothing_types_the_parameter() -> None:
    drive = entry()
    untyped = ParameterRef(1082, None, "p")
    assert drive.format_of(untyped, {}).vtype is None
    assert drive.format_of(untyped, {}, ValueType.U32).vtype is ValueType.U32
    typed = ParameterRef(1121, None, "p")
    assert drive.format_of(typed, {}, ValueType.U32) == TYPED  # the configuration's stays
