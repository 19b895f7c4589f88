"""One name per parameter on each drive."""

from __future__ import annotations

from pathlib import Path

import httpx
from prometheus_client.parser import text_string_to_metric_families

from tests.api.conftest import USS_DRIVES, fc_drives, service


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

        sent = len(svc.recorder.writes())
        for written in ("p0341", "P341", "r0341"):
            r = await svc.put("fan1", written, {"value": 1})
            assert r.status_code == 422, r.text
            error = r.json()["error"]
            assert error["kind"] == "wrong_notation"
            assert "Siemens notation" in error["message"] and "write 3-41" in error["message"]
        assert len(svc.recorder.writes()) == sent  # nothing sent

        metrics = (await svc.client.get("/metrics")).text
        assert 'parameter="16-13"' in metrics and 'parameter="1613"' not in metrics
        drives = (await svc.client.get("/api/v1/drives")).json()
        assert {v["parameter"] for d in drives for v in d["values"]} == {"16-13"}


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
