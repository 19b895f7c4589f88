"""GET /api/v1/drives keeps each drive's view in parts (its values, its head, its tail) and
makes a part again only when what it shows changed: after each kind of change, the answer
still says what the drive's view says now."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pkwbus.master.reading import Reading
from pkwbus.service.http.views.drives import drive_view
from tests.service.http.conftest import AUTH, fc_drives, service

QUIET = [("16-13", "60s"), ("16-14", "60s"), ("1-20", "60s")]


async def _same_as_the_views(svc: Any) -> dict[str, dict[str, Any]]:
    answer = (await svc.client.get("/api/v1/drives")).json()
    for got in answer:
        assert got == drive_view(svc.runtime, got["name"]).model_dump(mode="json"), got["name"]
    return {d["name"]: d for d in answer}


async def test_each_kept_part_follows_what_it_shows(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        before = await _same_as_the_views(svc)
        snap = svc.runtime.snapshot
        # the tail: a drive in maintenance
        r = await svc.client.put("/api/v1/drives/fan2/maintenance",
                                 json={"on": True, "reason": "belt"}, headers=AUTH)  # fmt: skip
        assert r.status_code == 200, r.text
        now = await _same_as_the_views(svc)
        assert now["fan2"]["maintenance"]["reason"] == "belt"
        assert before["fan2"]["maintenance"] is None
        # the tail: a writable parameter's latest value, confirmed by a write
        r = await svc.put("fan1", "3-41", {"value": 12.5}, headers=AUTH)
        assert r.status_code == 200, r.text
        now = await _same_as_the_views(svc)
        shown = {w["parameter"]: w["value"] for w in now["fan1"]["writable"]}
        assert shown["3-41"] == 12.5
        # the values: one reading replaced (by hand: the test is the snapshot's writer here)
        key = ("fan3", "16-13", 0)
        old = snap.readings[key]
        snap.readings[key] = Reading(123, 123, old.timestamp + 1.0)
        snap.changes.touch("fan3")
        now = await _same_as_the_views(svc)
        (value,) = [v for v in now["fan3"]["values"] if v["parameter"] == "16-13"]
        assert value["value"] == 123
        # a value gone, then back
        del snap.readings[key]
        snap.changes.touch("fan3")
        now = await _same_as_the_views(svc)
        assert "16-13" not in [v["parameter"] for v in now["fan3"]["values"]]
        snap.readings[key] = old
        snap.changes.touch("fan3")
        now = await _same_as_the_views(svc)
        assert "16-13" in [v["parameter"] for v in now["fan3"]["values"]]
        # the head: the drive down
        state = snap.drives["fan3"]
        snap.drives["fan3"] = type(state)(False, state.status_word, state.status_timestamp,
                                          state.main_actual)  # fmt: skip
        snap.changes.touch("fan3")
        now = await _same_as_the_views(svc)
        assert now["fan3"]["up"] is False
