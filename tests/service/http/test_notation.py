"""One name per parameter on each drive, and old values that are not stale."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
from prometheus_client.parser import text_string_to_metric_families

from tests.service.http.conftest import USS_DRIVES, fc_drives, service


async def gauge(client: httpx.AsyncClient, name: str, **labels: str) -> float | None:
    text = (await client.get("/metrics")).text
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name == name and labels.items() <= sample.labels.items():
                return sample.value
    return None


async def test_an_fc_drive_has_one_name_per_parameter(tmp_path: Path) -> None:
    # "1613" polled as configured before: its label is the drive's name for it
    async with service(tmp_path, fc=fc_drives(polls=[("1613", "50ms")])) as svc:
        for written, value in (("341", 11.5), ("0341", 12.5), ("03-41", 13.5), ("3-41", 14.5)):
            r = await svc.put("fan1", written, {"value": value})
            assert r.status_code == 200, r.text
            assert r.json()["parameter"] == "3-41"
        r = await svc.client.get("/api/v1/drives/fan1/parameters/1613")
        assert r.status_code == 200 and r.json()["parameter"] == "16-13"
        assert svc.audit is not None
        assert {row.parameter for row in svc.audit.latest(10)} == {"3-41"}

        sent = len(svc.audit_writer.writes())
        for written in ("p0341", "P341", "r0341"):
            r = await svc.put("fan1", written, {"value": 1})
            assert r.status_code == 422, r.text
            error = r.json()["error"]
            assert error["kind"] == "wrong_notation"
            assert "Siemens notation" in error["message"] and "write 3-41" in error["message"]
        assert len(svc.audit_writer.writes()) == sent  # nothing sent

        metrics = (await svc.client.get("/metrics")).text
        assert 'parameter="16-13"' in metrics and 'parameter="1613"' not in metrics
        drives = (await svc.client.get("/api/v1/drives")).json()
        names = {v["parameter"] for d in drives for v in d["values"]}
        assert "16-13" in names and "1613" not in names


async def test_a_siemens_drive_names_parameters_as_its_catalog(tmp_path: Path) -> None:
    async with service(tmp_path, fc=[], uss=USS_DRIVES) as svc:
        for written in ("1120", "P1120", "p01120"):
            r = await svc.put("pump1", written, {"value": 2.5})
            assert r.status_code == 200, r.text
            assert r.json()["parameter"] == "p1120"
        r = await svc.client.get("/api/v1/drives/pump1/parameters/21")
        assert r.status_code == 200 and r.json()["parameter"] == "r0021"
        assert svc.audit is not None
        assert {row.parameter for row in svc.audit.latest(10)} == {"p1120"}


async def test_the_old_value_is_the_one_the_drive_last_confirmed(tmp_path: Path) -> None:
    # 3-41 polled once at start (then hourly), 3-42 never polled
    fc = fc_drives(polls=[("16-13", "50ms"), ("3-41", "1h")])
    async with service(tmp_path, fc=fc) as svc:
        polled = svc.sim.drives[1].value(341) / 100
        for parameter, first in (("3-41", polled), ("3-42", None)):
            for value in (11.5, 12.5):
                r = await svc.put("fan1", parameter, {"value": value})
                assert r.status_code == 200, r.text
                assert r.json()["old_value"] == first
                first = value
        assert svc.audit is not None
        rows = list(reversed(svc.audit.latest(10)))
        assert [(r.parameter, r.old_value, r.new_value) for r in rows] == [
            ("3-41", polled, 11.5),
            ("3-41", 11.5, 12.5),
            ("3-42", None, 11.5),
            ("3-42", 11.5, 12.5),
        ]
        # the polled parameter shows the value the drive acknowledged
        reading = svc.runtime.snapshot.readings["fan1", "3-41", 0]
        assert (reading.value, reading.raw) == (12.5, 1250)
        assert (
            await gauge(svc.client, "pkwbus_parameter_value", drive="fan1", parameter="3-41")
            == 12.5
        )

        # writes queued together: each one's old value is the one before it
        values = [21.0, 22.0, 23.0]
        results = await asyncio.gather(*(svc.put("fan2", "3-42", {"value": v}) for v in values))
        assert all(r.status_code == 200 for r in results)
        chain = {r.json()["old_value"]: r.json()["value"] for r in results}
        rows = [r for r in svc.audit.latest(10) if r.drive == "fan2"]
        assert {row.old_value: row.new_value for row in rows} == chain
        old = None  # never polled: nothing known before the first
        for _ in values:
            old = chain[old]
        assert old == svc.sim.drives[2].value(342) / 100
