"""The service reads each drive's description of its parameters (AK 4) before their first
value: the drive's scaling wins over a catalog that differs, a parameter in no catalog is
decoded and named by the drive, a drive that refuses falls back to the catalog, and no value
is ever exported with a scaling about to change."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from pkwbus.catalog import load_catalog
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.values import Scaling, ValueType
from pkwbus.service.http.views.drives import drive_view
from pkwbus.service.metrics.devices import SnapshotCollector
from pkwbus.service.runtime import Runtime
from pkwbus.sim import SimTiming, Simulator
from pkwbus.sim.drives.catalogs import specs_from_catalog
from pkwbus.sim.drives.table import ParamSpec
from pkwbus.sim.profibus.line import DpSimulator
from tests.master.conftest import until
from tests.service.assembly.test_service_e2e import running, sample, samples

# A parameter no catalog has (Danfoss numbering 16-99: not a parameter of the catalog).
STRANGER = ParamSpec(1699, "TEST VALUE", ValueType.I32, -1, "A", live="current")


def fc_specs(conversion_of_16_14: int) -> tuple[ParamSpec, ...]:
    """The catalog's parameters as a drive has them, except 16-14's conversion index."""
    specs = []
    for spec in specs_from_catalog(Bus.FC, "danfoss-fc"):
        if spec.pnu == 1614:
            spec = dataclasses.replace(spec, conversion=conversion_of_16_14)
        specs.append(spec)
    return (*specs, STRANGER)


@contextmanager
def landed_values() -> Iterator[list[tuple[ReadingKey, Reading]]]:
    """Every value as it lands in the exposition, from the service's start."""
    seen: list[tuple[ReadingKey, Reading]] = []
    original = SnapshotCollector.landed

    def landed(self: SnapshotCollector, key: ReadingKey, reading: Reading) -> None:
        seen.append((key, reading))
        original(self, key, reading)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(SnapshotCollector, "landed", landed)
        yield seen


def config(url: str, drives: str, protocol: str = "fc") -> str:
    return f"""
lines:
  - name: l1
    port: "{url}"
    protocol: {protocol}
    baudrate: 115200
    timeout: 50ms
    retries: 1
    alarms: off  # the tests count the values that land
    counters: off
    drives:
{drives}"""


def info(runtime: Runtime, drive: str, parameter: str) -> dict[str, str]:
    for (name, labels), _ in samples(runtime).items():
        found = dict(labels)
        mine = found.get("drive") == drive and found.get("parameter") == parameter
        if name == "pkwbus_parameter_info" and mine:
            return found
    raise AssertionError(f"no pkwbus_parameter_info for {drive} {parameter}")


async def described(runtime: Runtime) -> None:
    """Until every drive's descriptions have settled where the service shows them (the
    runner tells its events in batches, after the planner)."""
    await until(lambda: not any(d.pending for d in runtime.snapshot.decoding.values()), timeout=20)


async def test_fc_drive_scaling_wins_and_no_value_goes_out_with_the_catalogs_first(
    caplog: pytest.LogCaptureFixture,
) -> None:
    catalog = load_catalog("danfoss-fc").get(1614)
    assert catalog is not None and catalog.conversion == -2
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3),
                    refuse_descriptions=[2])  # fmt: skip
    # Another model (15-40): drives of one kind describe alike, so it would share drive 1's.
    sim.drives[2].params.texts[1540] = b"FC-202"
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: described
        address: 1
        catalog: danfoss-fc
        settings: off  # described: only its polls
        poll: [{parameter: "16-14", every: 20ms}, {parameter: "16-99", every: 20ms}]
      - name: refusing
        address: 2
        catalog: danfoss-fc
        settings: off
        poll: [{parameter: "16-14", every: 20ms}]"""
    caplog.set_level(logging.INFO)
    try:
        with landed_values() as seen:
            async with running(config(server.url, drives)) as runtime:
                await described(runtime)
                await until(lambda: len({k for k, _ in seen}) == 3, timeout=20)
                mine = info(runtime, "described", "16-14")
                stranger = info(runtime, "described", "16-99")
                theirs = info(runtime, "refusing", "16-14")
                mismatch = sample(runtime, "pkwbus_catalog_mismatch", drive="described",
                                  parameter="16-14", field="scaling")  # fmt: skip
                again = sample(runtime, "pkwbus_catalog_mismatch", drive="refusing")
                view = {v.parameter: v for v in drive_view(runtime, "described").values}
    finally:
        await server.close()
    drive_factor = float(Scaling.conversion(-3).factor)
    catalog_factor = float(Scaling.conversion(-2).factor)
    by_key: dict[ReadingKey, list[Reading]] = {}
    for key, reading in seen:
        by_key.setdefault(key, []).append(reading)
    # Every value of the described drive, the first one too, in the drive's scaling.
    for reading in by_key[("described", "16-14", 0)]:
        assert reading.raw is not None
        assert reading.value == pytest.approx(reading.raw * drive_factor)
    # The refusing drive: the catalog stands.
    for reading in by_key[("refusing", "16-14", 0)]:
        assert reading.raw is not None
        assert reading.value == pytest.approx(reading.raw * catalog_factor)
    # A parameter in no catalog: decoded and named by the drive.
    for reading in by_key[("described", "16-99", 0)]:
        assert reading.raw is not None
        assert reading.value == pytest.approx(reading.raw * 0.1)
    assert (stranger["name"], stranger["type"], stranger["source"]) == (
        "TEST VALUE",
        "i32",
        "drive",
    )
    assert stranger["unit"] == "A"
    assert mine["source"] == "drive" and theirs["source"] == "catalog"
    # GET /api/v1/drives shows the same.
    assert (view["16-99"].name, view["16-99"].source, view["16-99"].unit) == (
        "TEST VALUE", "drive", "A",
    )  # fmt: skip
    assert view["16-14"].source == "drive"
    assert mismatch == 1.0 and again is None
    warnings = [r.getMessage() for r in caplog.records if "the catalog as" in r.getMessage()]
    assert len(warnings) == 1, warnings
    assert "described" in warnings[0] and "16-14" in warnings[0] and "scaling" in warnings[0]
    assert "x0.001" in warnings[0] and "x0.01" in warnings[0]
    refusals = [r.getMessage() for r in caplog.records if "has no description" in r.getMessage()]
    assert len(refusals) == 1 and "refusing" in refusals[0]


def uss_specs() -> tuple[ParamSpec, ...]:
    """The Siemens catalog's parameters, except that this drive keeps r0027 as an Integer32
    in hundredths of an ampere (the catalog says FloatingPoint32)."""
    specs = []
    for spec in specs_from_catalog(Bus.USS, "siemens-g120"):
        if spec.pnu == 27:
            spec = dataclasses.replace(spec, vtype=ValueType.I32, conversion=-2, scale=None)
        specs.append(spec)
    return tuple(specs)


async def test_uss_drive_type_and_scaling_win_over_the_catalog() -> None:
    catalog = load_catalog("siemens-g120").get(27)
    assert catalog is not None and catalog.type == "f32"
    sim = Simulator("uss", [1], timing=SimTiming(response_delay=0.0), specs=uss_specs())
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: g120
        address: 1
        catalog: siemens-g120
        poll: [{parameter: "r0027", every: 20ms}]"""
    try:
        with landed_values() as seen:
            async with running(config(server.url, drives, "uss")) as runtime:
                await described(runtime)
                await until(lambda: len(seen) >= 3, timeout=20)
                found = info(runtime, "g120", "r0027")
                fields = {
                    dict(labels)["field"]
                    for (name, labels), _ in samples(runtime).items()
                    if name == "pkwbus_catalog_mismatch"
                }
    finally:
        await server.close()
    for _, reading in seen:
        assert reading.raw is not None
        raw = reading.raw - (1 << 32) if reading.raw & 0x80000000 else reading.raw
        assert reading.value == pytest.approx(raw * 0.01)
    assert (found["type"], found["source"]) == ("i32", "drive")
    assert {"type", "scaling"} <= fields


async def test_configuration_comes_before_the_drive() -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: d
        address: 1
        catalog: danfoss-fc
        poll: [{parameter: "16-14", every: 20ms, conversion: -1, name: Current}]"""
    try:
        with landed_values() as seen:
            async with running(config(server.url, drives)) as runtime:
                await described(runtime)
                await until(lambda: len(seen) >= 2, timeout=20)
                found = info(runtime, "d", "16-14")
    finally:
        await server.close()
    for _, reading in seen:
        assert reading.raw is not None
        assert reading.value == pytest.approx(reading.raw * 0.1)
    assert (found["source"], found["name"]) == ("config", "Current")


async def test_describe_off_asks_nothing() -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    asked: list[Any] = []
    params = sim.drives[1].params
    original = params.execute

    def execute(req: Any) -> Any:
        asked.append(req)
        return original(req)

    params.execute = execute  # type: ignore[method-assign]
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = """
      - name: d
        address: 1
        catalog: danfoss-fc
        describe: off
        poll: [{parameter: "16-14", every: 20ms}]"""
    try:
        async with running(config(server.url, drives)) as runtime:
            await until(lambda: len(asked) >= 3, timeout=20)
            found = info(runtime, "d", "16-14")
    finally:
        await server.close()
    assert {r.ak for r in asked} == {1}
    assert found["source"] == "catalog"


async def test_danfoss_pcv_over_profibus_describes_itself_in_the_ppo() -> None:
    """Simulated without the catalog, the PROFIBUS slaves keep 1-20 in hundredths of a kW
    (conversion index -2) where the catalog says 1 (W): slave 8 describes it through the
    PPO's PKW words and is decoded so; slave 9 refuses AK 4 and keeps the catalog."""
    catalog = load_catalog("danfoss-fc").get(120)
    assert catalog is not None and catalog.conversion == 1
    sim = DpSimulator([8, 9], dialect="danfoss-pcv", timing=SimTiming(response_delay=0.001),
                      catalog=None, refuse_descriptions=[9])  # fmt: skip
    assert sim.drives[8].params.specs[120].conversion == -2
    server = await sim.serve_tcp("127.0.0.1", 0)
    drives = "\n".join(
        f"""      - name: s{a}
        address: {a}
        dialect: danfoss-pcv
        ident: 0x0402
        catalog: danfoss-fc
        poll: [{{parameter: "1-20", every: 50ms}}]"""
        for a in (8, 9)
    )
    text = f"""
lines:
  - name: dp
    port: "{server.url}"
    protocol: profibus
    baudrate: 19200
    slot_time: 50ms
    watchdog: 2s
    alarms: off  # the test counts the values that land
    counters: off
    drives:
{drives}"""
    try:
        with landed_values() as seen:
            async with running(text) as runtime:
                await described(runtime)
                await until(lambda: len({k for k, _ in seen}) == 2, timeout=30)
                sources = {d: info(runtime, d, "1-20")["source"] for d in ("s8", "s9")}
                mismatch = sample(runtime, "pkwbus_catalog_mismatch", drive="s8", field="scaling")
    finally:
        await server.close()
    for (drive, _, _), reading in seen:
        assert reading.raw is not None
        factor = 0.01 if drive == "s8" else 10
        assert reading.value == pytest.approx(reading.raw * factor), drive
    assert sources == {"s8": "drive", "s9": "catalog"}
    assert mismatch == 1.0
