"""A line's drive-memory marks (service.assembly.line_marks) with a fake mark store: what
is exported, the merge rule, the bound, and writing only on change, a failed put tried
again."""

from __future__ import annotations

import asyncio
import json
import logging
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.service.assembly.line_changes import CONFIGURED
from pkwbus.service.assembly.line_marks import MARK, Kept, LineMarks, encode, export, merge
from pkwbus.service.history.settings_store import SettingRow, SettingsStore
from pkwbus.service.history.store import DriveEvent, HistoryStore


def event(drive: str, key: str, seen: float, text: str = "") -> DriveEvent:
    return DriveEvent("l1", drive, key, "fault", "7", 7, text, None, None, "seen", "", seen)


def fill(path: Path, events: list[DriveEvent], baseline: int | None, swept: float) -> None:
    store = HistoryStore(path)
    store.add(events)
    store.close()
    if baseline is not None:
        settings = SettingsStore(path)
        row = SettingRow("d1", 100, 0, "1-00", baseline, str(baseline), swept, baseline,
                         str(baseline), swept, "sweep")  # fmt: skip
        settings.save([row])
        settings.swept("d1", "FC-302", swept)
        settings.close()


def baseline_of(path: Path) -> tuple[int | None, float | None]:
    settings = SettingsStore(path)
    kept = settings.load("d1")
    settings.close()
    rows = kept.rows or {}
    return (rows[(100, 0)].baseline_raw if rows else None), kept.swept


def test_merge_adds_entries_not_seen_here_and_keeps_those_seen(tmp_path: Path) -> None:
    first, second = tmp_path / "a.sqlite", tmp_path / "b.sqlite"
    fill(first, [event("d1", "k1", 10.0, "there"), event("d1", "k2", 11.0)], 5, 100.0)
    fill(second, [event("d1", "k1", 12.0, "here")], None, 0)
    doc = export(first, ["d1"])
    assert merge(second, doc) == 1  # k2 only
    store = HistoryStore(second)
    kept = {e.key: e for e in store.latest(drive="d1")}
    store.close()
    assert set(kept) == {"k1", "k2"}
    assert kept["k1"].text == "here"  # seen here: stays as seen here
    assert baseline_of(second) == (5, 100.0)  # none here: etcd's


def test_merge_keeps_the_newer_settings_of_a_drive(tmp_path: Path) -> None:
    first, second = tmp_path / "a.sqlite", tmp_path / "b.sqlite"
    fill(first, [], 5, 100.0)
    fill(second, [], 9, 200.0)  # swept later here
    merge(second, export(first, ["d1"]))
    assert baseline_of(second) == (9, 200.0)
    fill(first, [], 6, 300.0)  # then later there
    merge(second, export(first, ["d1"]))
    assert baseline_of(second) == (6, 300.0)


def test_export_is_only_the_lines_drives(tmp_path: Path) -> None:
    path = tmp_path / "h.sqlite"
    fill(path, [event("d1", "k1", 1.0), event("d9", "k1", 1.0)], None, 0)
    doc = export(path, ["d1"])
    assert [e[1] for e in doc["events"]] == ["d1"]


def test_encode_leaves_out_the_oldest_entries_past_the_bound() -> None:
    events = [["l1", "d1", f"k{i}", "fault", "7", 7, "x" * 50, None, None, "seen", "", i]
              for i in range(200)]  # fmt: skip
    doc = {"events": events, "maintenance": {"d1": "pump"}}
    whole, none_dropped = encode(doc, 1_000_000)
    assert none_dropped == 0 and len(json.loads(whole)["events"]) == 200
    data, dropped = encode(doc, 5000)
    assert len(data) <= 5000 and dropped > 0
    kept = json.loads(data)
    assert kept["maintenance"] == {"d1": "pump"}
    assert [e[2] for e in kept["events"]] == [f"k{i}" for i in range(dropped, 200)]  # newest
    with pytest.raises(ValueError):
        encode({"events": [], "settings": ["y" * 100]}, 50)


class FakeMarks:
    def __init__(self) -> None:
        self.kept: dict[tuple[str, str], bytes] = {}
        self.puts = 0
        self.refuse = False

    async def get(self, line: str, name: str) -> bytes | None:
        return self.kept.get((line, name))

    async def put(self, line: str, name: str, value: bytes) -> bool:
        self.puts += 1
        if self.refuse:
            return False
        self.kept[(line, name)] = value
        return True


class FakeRunner:
    def __init__(self) -> None:
        self.switched: list[tuple[str, bool, str]] = []

    def maintenance(
        self, drive: str, on: bool, reason: str = "", since: float | None = None
    ) -> None:
        self.switched.append((drive, on, reason))


class FakeRuntime(SimpleNamespace):
    """What LineMarks asks of the runtime: its snapshot, runners and the API's maintenance."""

    def __init__(self, maintenance: dict[str, Any], runners: dict[str, Any]) -> None:
        super().__init__(snapshot=SimpleNamespace(maintenance=maintenance), runners=runners)
        self.api_maintenance: dict[str, Any] = {}

    def hold_maintenance(self, drive: str, held: Any) -> Any:
        return self.api_maintenance.setdefault(drive, held)

    def end_maintenance(self, drive: str) -> None:
        self.api_maintenance.pop(drive, None)

    def show_maintenance(self, runner: Any, drive: str) -> None:
        held = self.api_maintenance[drive]
        runner.maintenance(drive, True, held.reason, since=held.since)


def fake_runtime(maintenance: dict[str, Any]) -> Any:
    return FakeRuntime(maintenance, {"l1": FakeRunner()})


async def test_written_on_change_only_and_a_failed_put_tried_again(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "h.sqlite"
    fill(path, [event("d1", "k1", 1.0)], 5, 10.0)
    marks = FakeMarks()
    runtime = fake_runtime({"d1": SimpleNamespace(reason="bearing")})
    line_marks = LineMarks(marks, runtime, path, lambda line: ["d1"], every=0.01)
    assert await line_marks.write("l1") and marks.puts == 1
    assert await line_marks.write("l1") and marks.puts == 1  # unchanged: not put again
    fill(path, [event("d1", "k2", 2.0)], None, 0)
    marks.refuse = True
    with caplog.at_level(logging.WARNING, "pkwbus.service.standby"):
        assert not await line_marks.write("l1")
        assert not await line_marks.write("l1")
    assert len([r for r in caplog.records if "could not be written" in r.message]) == 1
    marks.refuse = False
    line_marks.hold("l1")  # the writer tries again by itself
    for _ in range(500):
        if marks.puts > 3:
            break
        await asyncio.sleep(0.01)
    await line_marks.release("l1", flush=False)
    doc = json.loads(marks.kept[("l1", MARK)])
    assert [e[2] for e in doc["events"]] == ["k1", "k2"]
    assert doc["maintenance"] == {"d1": "bearing"}


async def test_loaded_marks_merge_and_put_drives_in_maintenance(tmp_path: Path) -> None:
    first, second = tmp_path / "a.sqlite", tmp_path / "b.sqlite"
    fill(first, [event("d1", "k1", 1.0)], 5, 10.0)
    marks = FakeMarks()
    drives = ["d1", "d2", "d3"]
    # d1 and d2 the API's there (d2's reason the file's word), d3 the file's
    held = {d: SimpleNamespace(reason=r, since=1.0)
            for d, r in [("d1", "bearing"), ("d2", CONFIGURED), ("d3", CONFIGURED)]}  # fmt: skip
    there_runtime = fake_runtime(held)
    there_runtime.api_maintenance.update(d1=held["d1"], d2=held["d2"])
    there = LineMarks(marks, there_runtime, first, lambda line: drives)
    assert await there.write("l1")
    runtime = fake_runtime({})
    here = LineMarks(marks, runtime, second, lambda line: drives)
    kept = await here.load("l1")
    assert kept == {"d1": Kept("bearing", True), "d2": Kept(CONFIGURED, True),
                    "d3": Kept(CONFIGURED, False)}  # fmt: skip
    here.maintained("l1", kept)
    assert sorted(runtime.api_maintenance) == ["d1", "d2"]  # the API's here: a reload keeps them
    assert sorted(runtime.runners["l1"].switched) == [
        ("d1", True, "bearing"),
        ("d2", True, CONFIGURED),
        ("d3", True, CONFIGURED),
    ]
    assert baseline_of(second) == (5, 10.0)
    assert await here.load("l2") == {}  # never written: nothing


async def test_the_marks_of_an_older_instance_tell_the_apis_maintenance_by_its_reason(
    tmp_path: Path,
) -> None:
    """A document without ``maintenance_by_api``: the file's reason is the file's."""
    marks = FakeMarks()
    doc = {"maintenance": {"d1": "pump", "d2": CONFIGURED}}
    marks.kept[("l1", MARK)] = json.dumps(doc).encode()
    here = LineMarks(marks, fake_runtime({}), None, lambda line: ["d1", "d2"])
    assert await here.load("l1") == {"d1": Kept("pump", True), "d2": Kept(CONFIGURED, False)}


async def test_unusable_marks_are_left_aside(tmp_path: Path) -> None:
    marks = FakeMarks()
    marks.kept[("l1", MARK)] = b"[1, 2"
    here = LineMarks(marks, fake_runtime({}), tmp_path / "h.sqlite", lambda line: ["d1"])
    assert await here.load("l1") == {}


class Saved:
    def __init__(self) -> None:
        self.saves = 0

    def save(self) -> None:
        self.saves += 1


async def test_the_describe_book_is_carried_and_its_own_entries_stay(tmp_path: Path) -> None:
    marks = FakeMarks()
    there_book = DescriptionBook()
    there_book.put("FC:302", 1613, DriveDescription(type_code=4, name="FREQUENCY"), [])
    there_book.put("FC:302", 120, DriveDescription(type_code=4, name="THERE", array=4), [0, 1])
    there = LineMarks(marks, fake_runtime({}), None, lambda line: ["d1"], book=there_book)
    assert await there.write("l1")
    book, saved = DescriptionBook(), Saved()
    book.put("FC:302", 120, DriveDescription(type_code=4, name="HERE", array=4), [0, 1, 2])
    here = LineMarks(marks, fake_runtime({}), None, lambda line: ["d1"], book=book, saved=saved)
    await here.load("l1")
    assert book.get("FC:302", 1613) == DriveDescription(type_code=4, name="FREQUENCY")
    found = book.get("FC:302", 120)
    assert found is not None and found.name == "HERE"  # read more of it here: it stays
    assert saved.saves == 1  # kept on disk too
    await here.load("l1")
    assert saved.saves == 1  # nothing new: not saved again


async def test_a_line_a_reload_removed_is_no_longer_written(tmp_path: Path) -> None:
    marks = FakeMarks()
    marks.refuse = True  # every turn tries again
    line_marks = LineMarks(marks, fake_runtime({}), None, lambda line: ["d1"], every=0.01)
    line_marks.hold("l1")
    for _ in range(500):
        if marks.puts >= 2:
            break
        await asyncio.sleep(0.01)
    assert marks.puts >= 2
    await line_marks.keep_only(["l2"])
    puts = marks.puts
    await asyncio.sleep(0.1)
    assert marks.puts == puts
