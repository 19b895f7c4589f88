"""A line's drive-memory marks (service.assembly.line_marks) cost what changed: a turn with no
change of what they are made of reads the history nothing and encodes nothing; each kind
of change (a new log entry, a pruned one, a settings baseline, a maintenance switch, a
describe-book save) makes them again once and puts them once, reading again only the part
that changed. Real history stores in a temporary folder, a fake etcd and runtime; the
reads of log entries and settings, the documents encoded and the book's JSON counted."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any, NamedTuple

import pytest

from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.assembly.line_marks import MARK, LineMarks
from pkwbus.service.history import marks as mark_document
from pkwbus.service.history.settings_store import SettingRow, SettingsStore
from pkwbus.service.history.store import DriveEvent, HistoryStore
from tests.service.standby_service.test_line_marks import FakeMarks as KeptMarks
from tests.service.standby_service.test_line_marks import FakeRuntime

IDLE_TURNS = 25


def event(drive: str, key: str, seen: float) -> DriveEvent:
    return DriveEvent("l1", drive, key, "fault", "7", 7, "", None, None, "seen", "", seen)


def baseline(drive: str, raw: int, when: float) -> SettingRow:
    return SettingRow(drive, 100, 0, "1-00", raw, str(raw), when, raw, str(raw), when, "sweep")


class FakeMarks(KeptMarks):
    def doc(self, line: str = "l1") -> dict[str, Any]:
        loaded: dict[str, Any] = json.loads(self.kept[(line, MARK)])
        return loaded


class Counted:
    """How many times the history's log entries and settings were read, a document
    encoded, and a describe book made JSON."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.events = self.settings = self.encodes = self.books = 0
        events, settings = mark_document.read_events, mark_document.read_settings
        fit, to_json = mark_document.fit, DescriptionBook.to_json

        def counted_events(*args: Any) -> Any:
            self.events += 1
            return events(*args)

        def counted_settings(*args: Any) -> Any:
            self.settings += 1
            return settings(*args)

        def counted_fit(*args: Any) -> tuple[bytes, int]:
            self.encodes += 1
            return fit(*args)

        def counted_to_json(made: DescriptionBook) -> dict[str, Any]:
            self.books += 1
            return to_json(made)

        monkeypatch.setattr(mark_document, "read_events", counted_events)
        monkeypatch.setattr(mark_document, "read_settings", counted_settings)
        monkeypatch.setattr(mark_document, "fit", counted_fit)
        monkeypatch.setattr(DescriptionBook, "to_json", counted_to_json)

    def now(self, puts: int) -> Counts:
        return Counts(self.events, self.settings, self.encodes, self.books, puts)


class Counts(NamedTuple):
    events: int  # reads of the line's log entries
    settings: int  # reads of its drives' settings
    encodes: int
    books: int  # the describe book made JSON
    puts: int

    def plus(self, events: int = 0, settings: int = 0, books: int = 0) -> Counts:
        """After one turn that made the marks again (read ``events``, ``settings``, made
        the book JSON ``books`` times) and put them."""
        return Counts(self.events + events, self.settings + settings, self.encodes + 1,
                      self.books + books, self.puts + 1)  # fmt: skip


class Keeper:
    """The describe book's keeper (service.assembly.description_file) as the marks see it."""

    def __init__(self, book: DescriptionBook) -> None:
        self.book = book
        self.saves = 0

    def save(self) -> None:
        self.saves += 1


class Setup:
    def __init__(self, folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
        path = folder / "history.sqlite"
        self.history = HistoryStore(path)
        self.settings = SettingsStore(path, self.history.changes)  # as the service wires it
        self.history.add([event("d1", "k1", 1.0), event("d2", "k1", 1.0)])
        self.settings.save([baseline("d1", 5, 10.0)])
        self.settings.swept("d1", "FC-302", 10.0)
        self.kept = Keeper(DescriptionBook())
        self.marks = FakeMarks()
        self.maintenance: dict[str, Any] = {}
        runtime = FakeRuntime(self.maintenance, {})
        lines = {"l1": ["d1", "d2"], "l2": ["d9"]}
        self.line_marks = LineMarks(
            self.marks, runtime, path, lambda line: lines.get(line, []),
            book=self.kept.book, saved=self.kept, changes=self.history.changes,
        )  # fmt: skip
        self.counted = Counted(monkeypatch)

    def close(self) -> None:
        self.settings.close()
        self.history.close()

    def now(self) -> Counts:
        return self.counted.now(self.marks.puts)

    async def idle(self) -> None:
        """Turns with no change: nothing read, encoded, made JSON or put."""
        before = self.now()
        for _ in range(IDLE_TURNS):
            assert await self.line_marks.write("l1")
        assert self.now() == before

    async def once(self, events: int = 0, settings: int = 0, books: int = 0) -> None:
        """The turn after a change: made again once, reading what changed alone, put once;
        then idle again."""
        before = self.now()
        assert await self.line_marks.write("l1")
        assert self.now() == before.plus(events, settings, books)
        await self.idle()


@pytest.fixture
def setup(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    made = Setup(tmp_path, monkeypatch)
    yield made
    made.close()


async def test_idle_turns_read_and_encode_nothing(setup: Setup) -> None:
    assert await setup.line_marks.write("l1")  # the first: made and put
    assert setup.now() == (1, 1, 1, 1, 1)
    await setup.idle()
    assert [e[2] for e in setup.marks.doc()["events"]] == ["k1", "k1"]


async def test_each_change_makes_the_marks_once_and_puts_them_once(setup: Setup) -> None:
    assert await setup.line_marks.write("l1")
    await setup.idle()

    setup.history.add([event("d1", "k2", 2.0)])  # a new log entry
    await setup.once(events=1)
    assert [e[2] for e in setup.marks.doc()["events"] if e[1] == "d1"] == ["k1", "k2"]

    setup.history.add([event("d1", "k2", 2.0)])  # told again: nothing new, nothing made
    await setup.idle()

    setup.settings.save([baseline("d1", 6, 20.0)])  # a settings baseline
    await setup.once(settings=1)
    assert setup.marks.doc()["settings"][0][7] == 6

    setup.settings.swept("d1", "FC-302", 30.0)  # a sweep's end
    await setup.once(settings=1)
    assert setup.marks.doc()["swept"] == [["d1", "FC-302", 30.0]]

    setup.maintenance["d2"] = SimpleNamespace(reason="pump")  # a maintenance switch
    await setup.once()
    assert setup.marks.doc()["maintenance"] == {"d2": "pump"}
    del setup.maintenance["d2"]
    await setup.once()
    assert setup.marks.doc()["maintenance"] == {}

    setup.kept.book.put("FC:302", 1613, DriveDescription(type_code=4, name="FREQUENCY"), [])
    setup.kept.save()  # a describe-book save
    await setup.once(books=1)
    assert "FC:302" in setup.marks.doc()["book"]["drives"]

    assert setup.history.prune("d2", ["fault"], [], before=5.0) == 1  # an entry pruned
    await setup.once(events=1)
    assert [e[1] for e in setup.marks.doc()["events"]] == ["d1", "d1"]


async def test_another_lines_changes_make_nothing_here(setup: Setup) -> None:
    assert await setup.line_marks.write("l1")
    setup.history.add([event("d9", "k1", 3.0)])
    setup.settings.save([baseline("d9", 1, 3.0)])
    setup.maintenance["d9"] = SimpleNamespace(reason="elsewhere")
    await setup.idle()


async def test_a_failed_put_is_tried_again_without_making_the_marks_again(setup: Setup) -> None:
    assert await setup.line_marks.write("l1")
    setup.history.add([event("d1", "k2", 2.0)])
    setup.marks.refuse = True
    assert not await setup.line_marks.write("l1")
    assert not await setup.line_marks.write("l1")
    assert setup.now() == (2, 1, 2, 1, 3)  # made once, put twice (refused)
    setup.marks.refuse = False
    assert await setup.line_marks.write("l1")
    assert setup.now() == (2, 1, 2, 1, 4)
    await setup.idle()
    assert [e[2] for e in setup.marks.doc()["events"] if e[1] == "d1"] == ["k1", "k2"]


async def test_held_again_the_marks_are_made_afresh(setup: Setup) -> None:
    assert await setup.line_marks.write("l1")
    await setup.line_marks.release("l1", flush=False)
    await setup.once(events=1, settings=1)  # nothing changed, but etcd's is not known


async def test_merged_marks_count_as_a_change_of_their_drives(setup: Setup) -> None:
    doc = {"events": [["l1", "d2", "k7", "fault", "7", 7, "", None, None, "seen", "", 4.0]]}
    setup.marks.kept[("l3", MARK)] = json.dumps(doc).encode()
    assert await setup.line_marks.write("l1")
    await setup.line_marks.load("l3")  # a line won whose marks name d2 (of l1 here)
    await setup.once(events=1, settings=1)
    assert "k7" in [e[2] for e in setup.marks.doc()["events"]]


async def test_without_counts_every_turn_reads_as_before(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "history.sqlite"
    store = HistoryStore(path)
    store.add([event("d1", "k1", 1.0)])
    store.close()
    marks = FakeMarks()
    runtime = FakeRuntime({}, {})
    plain = LineMarks(marks, runtime, path, lambda line: ["d1"])  # no counts given
    counted = Counted(monkeypatch)
    for _ in range(3):
        assert await plain.write("l1")
    assert counted.now(marks.puts) == (3, 3, 3, 0, 1)  # read each turn, put once


def test_the_book_keeper_counts_its_saves(tmp_path: Path) -> None:
    kept = DescriptionFile(tmp_path / "descriptions.json")
    assert kept.saves == 0
    kept.book.put("FC:302", 1613, DriveDescription(type_code=4, name="FREQUENCY"), [])
    kept.save()
    kept.save()
    assert kept.saves == 2
    assert kept.flush(10.0)
