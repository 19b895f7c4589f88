"""GET /api/v1/drives keeps each drive's view in parts (its values, its head, its tail) and
makes a part again only when what it shows changed: after each kind of change, the answer
still says what the drive's view says now."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pkwbus.master.reading import Reading
from pkwbus.service.http.views import drives as drives_view
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


async def test_a_new_reading_of_the_same_value_changes_only_its_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A value read again (the same number, a new time: most polls) is not made again from
    its fields: its piece is the kept one with the new time, and still what the drive's view
    says. Another value, or the same number of another type, is made again."""
    made: list[str] = []
    fields = drives_view._reading_fields

    def counted(*args: Any) -> dict[str, Any]:
        made.append(args[1].parameter)
        return fields(*args)

    monkeypatch.setattr(drives_view, "_reading_fields", counted)
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        await _same_as_the_views(svc)
        snap = svc.runtime.snapshot
        key = ("fan3", "16-13", 0)
        old = snap.readings[key]
        for value, raw, again in ((old.value, old.raw, False), (123, 123, True),
                                  (123, 123, False), (123.0, 123, True)):  # fmt: skip
            stamp = snap.readings[key].timestamp + 1.25
            snap.readings[key] = Reading(value, raw, stamp)
            snap.changes.touch("fan3")
            made.clear()
            answer = (await svc.client.get("/api/v1/drives?drive=fan3")).json()
            assert made == (["16-13"] if again else []), (value, made)
            (view,) = answer
            assert view == drive_view(svc.runtime, "fan3").model_dump(mode="json")
            (got,) = [v for v in view["values"] if v["parameter"] == "16-13"]
            assert got["timestamp"] == stamp and got["value"] == value
            assert type(got["value"]) is type(value)


async def test_the_writable_part_follows_the_value_not_the_reading(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A writable parameter shows its latest value: a new reading of the same value leaves
    the drive's tail as it was; another value (or the same number of another type) makes
    it again, and the answer is still what the drive's view says."""
    made: list[str] = []
    tail = drives_view.DriveViews._tail_json

    def counted(self: Any, name: str, *args: Any) -> bytes:
        made.append(name)
        return tail(self, name, *args)

    monkeypatch.setattr(drives_view.DriveViews, "_tail_json", counted)
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        r = await svc.put("fan1", "3-41", {"value": 12.5}, headers=AUTH)
        assert r.status_code == 200, r.text
        await svc.client.get("/api/v1/drives?drive=fan1")
        snap = svc.runtime.snapshot
        (key,) = [k for k in snap.latest if k[0] == "fan1" and k[1] == 341]
        for value, again in ((12.5, False), (13.0, True), (13.0, False), (13, True)):
            old = snap.latest[key]
            snap.latest[key] = Reading(value, old.raw, old.timestamp + 1.0)
            snap.changes.touch("fan1")
            made.clear()
            (view,) = (await svc.client.get("/api/v1/drives?drive=fan1")).json()
            assert made == (["fan1"] if again else []), (value, made)
            assert view == drive_view(svc.runtime, "fan1").model_dump(mode="json")
            (shown,) = [w for w in view["writable"] if w["parameter"] == "3-41"]
            assert shown["value"] == value and type(shown["value"]) is type(value)


async def test_a_drive_says_how_many_values_it_polls_before_any_is_read(tmp_path: Path) -> None:
    """``polled`` is the number of values the drive polls, read or not: a drive none of
    whose values landed yet is told apart from one that polls nothing (the page says
    which)."""
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        polls = {n: len(e.polls) for n, e in svc.runtime.drives.items()}  # with the defaults
        assert min(polls.values()) >= len(QUIET)
        now = await _same_as_the_views(svc)
        assert {n: d["polled"] for n, d in now.items()} == polls
        snap = svc.runtime.snapshot
        for key in [k for k in snap.readings if k[0] == "fan3"]:
            del snap.readings[key]  # by hand: the test is the snapshot's writer here
        snap.changes.touch("fan3")
        now = await _same_as_the_views(svc)
        assert now["fan3"]["values"] == [] and now["fan3"]["polled"] == polls["fan3"]
