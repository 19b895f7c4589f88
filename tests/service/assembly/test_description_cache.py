"""Drive descriptions kept between runs, by drive identity (FC 15-40 and 15-43): a restart
describes nothing again, a drive of another model is described afresh, and a drive replaced
while the service runs is described again before its next value goes out."""

from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path
from typing import Any

import pytest

from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.values import Scaling
from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.config import parse_config
from pkwbus.sim import SimTiming, Simulator
from tests.master.conftest import until
from tests.service.assembly.test_descriptions import config, described, fc_specs, landed_values

Landed = list[tuple[ReadingKey, Reading]]

DRIVES = """
      - name: d
        address: 1
        catalog: danfoss-fc
        settings: off  # described: only its polls
        poll: [{parameter: "16-14", every: 20ms}]"""


def asked(sim: Simulator) -> list[Any]:
    """Every description request (AK 4) the drive executes, from now on."""
    seen: list[Any] = []
    params = sim.drives[1].params
    original = params.execute

    def execute(req: Any) -> Any:
        if req.command is Command.READ_DESCRIPTION:
            seen.append(req)
        return original(req)

    params.execute = execute  # type: ignore[method-assign]
    return seen


async def run_once(
    sim: Simulator, path: Path
) -> tuple[list[Any], list[tuple[ReadingKey, Reading]]]:
    """One run of the service until the drive is described and two values came."""
    requests = asked(sim)
    server = await sim.serve_tcp("127.0.0.1", 0)
    kept = DescriptionFile(path)
    try:
        with landed_values() as seen:
            runtime = await build_runtime(
                parse_config(config(server.url, DRIVES), environ={}), kept
            )
            await runtime.start()
            try:
                await described(runtime)
                await until(lambda: len(seen) >= 2, timeout=20)
            finally:
                await runtime.stop()
    finally:
        await server.close()
        await kept.settled()  # written by a thread of its own: as the service's stop waits
    return requests, seen


def scaled_by(seen: Landed, conversion: int) -> bool:
    """Every value of 16-14 (the polled one; not the counters polled by default) scaled so."""
    factor = float(Scaling.conversion(conversion).factor)
    currents = [r for key, r in seen if key[1] == "16-14"]
    return bool(currents) and all(
        r.raw is not None and r.value == pytest.approx(r.raw * factor) for r in currents
    )


async def test_a_restart_describes_nothing_again_and_another_model_is_described(
    tmp_path: Path,
) -> None:
    path = tmp_path / "audit.sqlite.descriptions.json"
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    first, seen = await run_once(sim, path)
    assert first and scaled_by(seen, -3)
    kept = json.loads(path.read_text())["drives"]
    (identity,) = kept
    assert identity.startswith("fc:FC-102")
    assert kept[identity]["1614"]["description"]["conversion"] == -3
    assert kept[identity]["1614"]["elements"] == [1, 2, 4, 6]

    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    again, seen = await run_once(sim, path)
    assert again == [] and scaled_by(seen, -3)  # the drive's scaling, from the file

    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-1))
    sim.drives[1].params.texts[1540] = b"FC-302"  # another model at the same address
    other, seen = await run_once(sim, path)
    assert other and scaled_by(seen, -1)
    assert len(json.loads(path.read_text())["drives"]) == 2


async def test_a_file_that_is_not_descriptions_is_logged_and_started_afresh(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "descriptions.json"
    path.write_text('{"format": 1, "drives": {"fc:FC-102|05.11": {"1614": {"conversion": 99}}}}')
    caplog.set_level(logging.WARNING)
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    requests, seen = await run_once(sim, path)
    assert requests and scaled_by(seen, -3)
    assert any("not a file of drive descriptions" in r.getMessage() for r in caplog.records)
    (kept,) = json.loads(path.read_text())["drives"].values()  # written afresh
    assert kept["1614"]["description"]["conversion"] == -3


async def test_a_drive_replaced_while_running_is_described_before_its_next_value(
    tmp_path: Path,
) -> None:
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), specs=fc_specs(-3))
    requests = asked(sim)
    server = await sim.serve_tcp("127.0.0.1", 0)
    text = config(server.url, DRIVES)
    try:
        with landed_values() as seen:
            runtime = await build_runtime(parse_config(text, environ={}), None)
            await runtime.start()
            try:
                await described(runtime)
                await until(lambda: len(seen) >= 2, timeout=20)
                before = len(requests)
                sim.kill(1)
                await until(lambda: not runtime.snapshot.drives["d"].up, timeout=20)
                changed = len(seen)
                drive = sim.drives[1]
                drive.params.texts[1540] = b"FC-302"
                spec = drive.params.specs[1614]
                drive.params.specs[1614] = dataclasses.replace(spec, conversion=-1)
                sim.revive(1)
                await until(lambda: len(seen) >= changed + 2, timeout=20)
            finally:
                await runtime.stop()
    finally:
        await server.close()
    assert len(requests) > before  # described afresh
    assert scaled_by(seen[:changed], -3)
    assert scaled_by(seen[changed:], -1)  # not one value of the new drive in the old scaling


def test_a_file_that_cannot_be_written_is_one_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    kept = DescriptionFile(blocker / "audit.sqlite.descriptions.json")
    caplog.set_level(logging.INFO)
    for conversion in (-1, -2, -3):
        described = DriveDescription(type_code=4, conversion=conversion)
        kept.book.put("fc:FC-302|05.11", 1614, described, (1, 2, 4, 6))
        kept.save()
        assert kept.flush(10.0)
    stores = [r for r in caplog.records if "cannot store" in r.getMessage()]
    assert len(stores) == 1 and stores[0].levelno == logging.WARNING


@pytest.mark.parametrize(
    "text",
    [
        "[" * 100_000,  # nested past the parser's recursion
        '{"format": 2, "drives": {}}',
        '{"format": 1, "drives": {"x": {"1614": {"elements": [1], "description": {}}}}}',
        '{"format": 1, "drives": {"x": {"a": {"elements": [1], "description": null}}}}',
    ],
)
def test_no_cache_file_stops_the_service(text: str, tmp_path: Path) -> None:
    path = tmp_path / "descriptions.json"
    path.write_text(text)
    assert DescriptionFile(path).book.entries == {}


@pytest.mark.parametrize(
    ("field", "value"),
    [("low_raw", "NaN"), ("high_raw", "Infinity"), ("array", 0), ("array", 1.5),
     ("type_code", 300), ("conversion", 99), ("read_only", 1)],
)  # fmt: skip
def test_a_cache_files_values_are_checked(field: str, value: object, tmp_path: Path) -> None:
    good = dataclasses.asdict(DriveDescription(type_code=4, conversion=-2, low_raw=0))
    entry = {"elements": [1, 2, 4, 6], "description": {**good, field: value}}
    text = json.dumps({"format": 1, "drives": {"fc:x": {"1614": entry}}})
    path = tmp_path / "descriptions.json"
    path.write_text(text.replace('"NaN"', "NaN").replace('"Infinity"', "Infinity"))
    assert DescriptionFile(path).book.entries == {}
    path.write_text(json.dumps({"format": 1, "drives": {"fc:x": {"1614": {**entry,
                    "description": good}}}}))  # fmt: skip
    assert DescriptionFile(path).book.get("fc:x", 1614) is not None
