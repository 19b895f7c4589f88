"""Each drive's parameters are resolved once when the service is built: the runtime
looks them up in a plain table and holds no configuration model."""

from __future__ import annotations

import dataclasses
import gc
import weakref
from collections.abc import Iterator, Mapping
from types import FunctionType, MethodType

import pytest
from pydantic import BaseModel

from pkwbus.catalog import ParameterDescription, load_catalog
from pkwbus.catalog.alarms import CodeTable, WordTable
from pkwbus.protocol.values import ParameterRef, parse_parameter
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import Config, parse_config
from pkwbus.service.config.resolved import explicit_layers, parameter_table
from pkwbus.service.runtime import DriveEntry, Runtime

CONFIG = """
audit_db: ":memory:"
lines:
  - name: l1
    port: socket://127.0.0.1:9
    protocol: fc
    baudrate: 19200
    drives:
      - name: fan
        address: 1
        catalog: danfoss-fc
        poll:
          - {parameter: "16-13", every: 1s, scale: 1, unit: rpm}
          - {parameter: "15-30", every: 1s, unit: code}
        writable: ["0341", "3-42[1]"]
        parameters:
          "3-41": {min: 1, max: 60}
          "3-42[1]": {max: 30}
  - name: l2
    port: socket://127.0.0.1:10
    protocol: uss
    baudrate: 19200
    drives:
      - name: pump
        address: 2
        poll:
          - {parameter: "r0021", every: 1s, type: f32, unit: Hz}
        writable: ["p1082"]
        parameters:
          "p1082": {type: f32, min: 0, max: 50}
"""


async def built() -> tuple[Runtime, weakref.ref[Config]]:
    config = parse_config(CONFIG, environ={})
    runtime = await build_runtime(config)
    return runtime, weakref.ref(config)


def ref(text: str) -> ParameterRef:
    return parse_parameter(text)


async def test_the_table_holds_the_catalog_merged_with_the_overrides() -> None:
    runtime, _ = await built()
    fan = runtime.drives["fan"]
    catalog = load_catalog("danfoss-fc")
    ramp = fan.format_of(ref("3-41"), {})
    spec = catalog.get(341)
    assert spec is not None
    assert (ramp.minimum, ramp.maximum, ramp.unit) == (1, 60, spec.unit)
    assert ramp.scaling == ParameterDescription.from_spec(spec).scaling
    assert fan.may_write(ref("3-41")) and fan.may_write(ref("3-41[4]"))
    speed = fan.format_of(ref("16-13"), {})
    assert (speed.unit, speed.scaling.factor, speed.writable) == ("rpm", 1, False)
    # Only index 1 of 3-42 is writable, with its own limit; the catalog's default is not enough.
    assert fan.may_write(ref("3-42[1]")) and fan.format_of(ref("3-42[1]"), {}).maximum == 30
    assert not fan.may_write(ref("3-42[2]")) and fan.format_of(ref("3-42[2]"), {}).maximum is None
    assert catalog.parameters[414].writable and not fan.may_write(ref("4-14"))
    assert fan.canonical(ref("341")).name == "3-41"
    pump = runtime.drives["pump"]
    limits = pump.format_of(ref("1082"), {})
    assert (limits.minimum, limits.maximum, limits.writable) == (0, 50, True)
    assert pump.canonical(ref("1082")).name == "p1082"
    assert pump.canonical(ref("21")).name == "r0021"
    assert pump.format_of(ref("2000"), {}) == ParameterDescription()
    formats = {d: runtime.snapshot.decoding[d].formats for d in ("pump", "fan")}
    assert formats["pump"][("r0021", 0)].unit == "Hz" and formats["fan"][("16-13", 0)].unit == "rpm"


@pytest.mark.parametrize("drive", ["fan", "pump"])
def test_the_table_says_what_the_configuration_says_of_every_parameter(drive: str) -> None:
    """Resolved once, the same as asking the configuration each time: catalog and
    named parameters, each index the configuration names and one it does not."""
    config = parse_config(CONFIG, environ={})
    found = next(d for _, d in config.drives() if d.name == drive)
    table = parameter_table(found)
    pnus = {r.pnu for _, r in found.refs()} | set(load_catalog("danfoss-fc").parameters) | {7}
    for pnu in sorted(pnus):
        for index in (None, 0, 1, 2, 200):
            given = found.canonical(ParameterRef(pnu, index, str(pnu)))
            assert table.canonical(ParameterRef(pnu, index, str(pnu))) == given
            want = ParameterDescription.from_spec(found.spec(given))
            got = table.describe(given)
            assert dataclasses.replace(got, writable=False, prefix="") == dataclasses.replace(
                want, writable=False, prefix=""
            ), given
            assert got.writable == found.may_write(given), given


def test_element_0_of_a_parameter_that_is_no_array_is_the_parameter_itself() -> None:
    """The limits given for 3-41[0] (no array in the catalog: the same telegram as 3-41) hold
    for 3-41 too, in the table and in the layers a drive's own description goes between;
    those given for 15-30[0] (an array of 10) stay with element 0."""
    text = CONFIG.replace('"3-41": {min: 1, max: 60}', '"3-41[0]": {min: 1, max: 45}').replace(
        '"3-42[1]": {max: 30}', '"3-42[1]": {max: 30}\n          "15-30[0]": {max: 5}'
    )
    config = parse_config(text, environ={})
    fan = next(d for _, d in config.drives() if d.name == "fan")
    table = parameter_table(fan)
    for given in ("3-41", "3-41[0]"):
        found = table.describe(fan.canonical(ref(given)))
        assert (found.minimum, found.maximum, found.writable) == (1, 45, True), given
    layers = explicit_layers(fan, table)
    assert layers[(341, None)].config.maximum == 45
    assert table.describe(fan.canonical(ref("15-30[0]"))).maximum == 5
    assert table.describe(fan.canonical(ref("15-30"))).maximum is None
    assert layers[(1530, None)].config.maximum is None


def objects(root: object, seen: set[int] | None = None) -> Iterator[object]:
    """Everything reachable from ``root`` through dataclass fields, mappings and tuples."""
    seen = set() if seen is None else seen
    if id(root) in seen:
        return
    seen.add(id(root))
    yield root
    children: list[object] = []
    if dataclasses.is_dataclass(root) and not isinstance(root, type):
        children = [getattr(root, f.name) for f in dataclasses.fields(root)]
    elif isinstance(root, Mapping):
        children = [*root.keys(), *root.values()]
    elif isinstance(root, tuple | list | set | frozenset):
        children = list(root)
    for child in children:
        yield from objects(child, seen)


async def test_the_runtime_holds_no_configuration_model() -> None:
    runtime, config = await built()
    gc.collect()
    assert config() is None, "the runtime keeps the configuration alive"
    for entry in runtime.drives.values():
        assert isinstance(entry, DriveEntry)
        for found in objects(entry):
            if isinstance(found, WordTable | CodeTable):
                continue  # an alarm table's entry: the catalog's, shared by every drive
            assert not isinstance(found, BaseModel | FunctionType | MethodType), found
