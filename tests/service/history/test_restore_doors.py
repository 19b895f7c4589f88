"""One restore through both doors: the API's ``POST .../restore`` and ``pkwbus restore``
plan the same writes from the same backup and skip the same settings with the same
reasons; a readout the catalog knows (15-00 Operating hours, a counter the drive keeps)
is never planned, whatever the drive describes."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from pkwbus.catalog import load_catalog
from pkwbus.protocol.values import danfoss_name
from tests.commands.test_settings_cli import Served, fc_simulator, line, run
from tests.service.http.conftest import AUTH, fc_drives, service
from tests.service.http.test_settings import swept, until

COUNTER = 1500  # 15-00 Operating hours: a counter in the danfoss-fc catalog


def backup_document(values: dict[int, int]) -> dict[str, Any]:
    """A backup of a Danfoss drive of the default catalog, with ``values`` (PNU: value)."""
    return {
        "pkwbus_backup": 1,
        "drive": "fan9",
        "dialect": "fc",
        "catalog": "danfoss-fc",
        "settings": [
            {"parameter": danfoss_name(pnu), "index": 0, "value": value}
            for pnu, value in values.items()
        ],
    }


def test_the_catalog_calls_15_00_a_counter() -> None:
    spec = load_catalog("danfoss-fc").get(COUNTER)
    assert spec is not None and spec.counter


def plan_of(answer: dict[str, Any]) -> tuple[set[str], dict[str, str]]:
    planned = {p["parameter"] for p in answer["plan"]}
    return planned, {s["parameter"]: s["why"] for s in answer["skipped"]}


@pytest.fixture
def fc() -> Iterator[Served]:
    served = Served(fc_simulator())
    yield served
    served.close()


@pytest.fixture
def document() -> dict[str, Any]:
    # 3-41 differs from the factory value on both doors' drives; 15-00 is a readout.
    return backup_document({341: 1234, 342: 1000, COUNTER: 99})


async def test_the_api_never_plans_a_readout(tmp_path: Path, document: dict[str, Any]) -> None:
    async with service(tmp_path, fc=fc_drives()[:1], settings="{every: 1s}") as svc:
        await until(swept(svc, "fan1"))
        body = {"backup": document, "dry_run": True, "force": True}
        r = await svc.client.post("/api/v1/drives/fan1/restore", json=body, headers=AUTH)
        assert r.status_code == 200, r.text
        planned, skipped = plan_of(r.json())
    assert "3-41" in planned and "15-00" not in planned
    assert skipped["15-00"].startswith("a readout")


def test_the_command_never_plans_a_readout(
    capsys: pytest.CaptureFixture[str], fc: Served, tmp_path: Path, document: dict[str, Any]
) -> None:
    path = tmp_path / "backup.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    code, out, err = run(
        capsys, "restore", str(path), *line(fc, 2), "--dry-run", "--json", "--force"
    )
    assert code == 0, err
    planned, skipped = plan_of(json.loads(out))
    assert "3-41" in planned and "15-00" not in planned
    assert skipped["15-00"].startswith("a readout")
    assert fc.drive(2).value(COUNTER) != 99, "nothing written"
