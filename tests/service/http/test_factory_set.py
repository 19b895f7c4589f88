"""The service with its defaults (pkw_words: auto) on a USS line of drives as Siemens ships
them (a variable PKW length, the simulator's default): word and float values read, a float
written, the length learned and no conflict exported."""

from __future__ import annotations

import logging
import struct
from pathlib import Path

import pytest
from prometheus_client import generate_latest

from tests.service.http.conftest import USS_DRIVES, service


async def test_a_factory_set_drive_with_the_defaults(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO)
    async with service(tmp_path, fc=[], uss=USS_DRIVES) as svc:
        drive = svc.sims["uss"].drives[1]
        assert drive.shape.pkw_words is None  # the simulator is as the factory sets it
        r = await svc.client.get("/api/v1/drives/pump1/parameters/r0947", params={"index": 0})
        assert r.status_code == 200, r.text
        assert r.json()["raw"] == drive.value(947, 0)  # a word, read
        r = await svc.put("pump1", "p1120", {"value": 12.5})
        assert r.status_code == 200, r.text
        assert drive.value(1120) == int.from_bytes(struct.pack(">f", 12.5), "big")
        metrics = generate_latest(svc.runtime.registry).decode()
    assert 'pkwbus_drive_pkw_length_conflict{drive="pump1",line="line_uss"} 0.0' in metrics
    learned = [
        r.getMessage() for r in caplog.records if "learned from its answers" in r.getMessage()
    ]
    assert learned == ["drive pump1: PKW length 127 (variable), learned from its answers"]
