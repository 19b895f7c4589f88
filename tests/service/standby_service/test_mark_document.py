"""A line's marks as a document (service.history.marks): encoded from text parts, the
same bytes and the same entries left out as one JSON dump of the whole document cut down
entry by entry; made again from the last one's parts, the same as made afresh."""

from __future__ import annotations

import json
import random
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from pkwbus.service.history.marks import encode, export, make
from pkwbus.service.history.settings_store import SettingRow, SettingsStore
from pkwbus.service.history.store import EVENTS, SETTINGS, DriveEvent, HistoryStore


def whole(doc: Mapping[str, Any], limit: int) -> tuple[bytes, int]:
    """The document dumped whole, again each time entries are left out (the rule: about
    the share over the limit, at least one)."""
    events = list(doc.get("events", []))
    dropped = 0
    while True:
        data = json.dumps({**doc, "events": events[dropped:]}, separators=(",", ":")).encode()
        if len(data) <= limit:
            return data, dropped
        if dropped >= len(events):
            raise ValueError("too big")
        over = (len(data) - limit) / len(data)
        dropped = min(len(events), dropped + max(1, int((len(events) - dropped) * over) + 1))


def entry(i: int, rng: random.Random) -> list[Any]:
    text = "".join(rng.choice('aé"\\ü\n') for _ in range(rng.randrange(0, 40)))
    return ["l1", f"d{i % 5}", f"k{i}", "fault", "7", 7, text, None, rng.random(), "seen", "", i]


@pytest.mark.parametrize("events_first", [True, False])
def test_the_parts_encode_as_the_whole_under_any_bound(events_first: bool) -> None:
    rng = random.Random(7)
    events = [entry(i, rng) for i in range(300)]
    rest = {"settings": [["d1", 100, 0, "1-00", 5, "5", 1.0, 5, "5", 1.0, "sweep", None]],
            "maintenance": {"d2": "pump ü"}, "book": {"format": 1, "drives": {}}}  # fmt: skip
    doc = {"events": events, **rest} if events_first else {**rest, "events": events}
    size = len(whole(doc, 10**9)[0])
    for limit in [size, size - 1, size // 2, size // 7, 400, 1000, 5000]:
        assert encode(doc, limit) == whole(doc, limit)
    assert encode({"maintenance": {}}, 100) == whole({"maintenance": {}}, 100)
    with pytest.raises(ValueError):
        encode(doc, 100)  # the rest alone is more


def test_made_again_from_the_last_parts_is_made_afresh(tmp_path: Path) -> None:
    path = tmp_path / "history.sqlite"
    history = HistoryStore(path)
    settings = SettingsStore(path, history.changes)
    drives = ("d1", "d2")
    history.add([DriveEvent("l1", d, f"k{i}", "fault", "7", 7, "", None, None, "seen", "", i)
                 for i in range(40) for d in drives])  # fmt: skip
    extra = [("maintenance", '{"d1":"pump"}')]

    def counts() -> tuple[int | None, int | None]:
        return history.changes.count(EVENTS, drives), history.changes.count(SETTINGS, drives)

    def afresh(limit: int) -> tuple[bytes, int]:
        return encode({**export(path, drives), "maintenance": {"d1": "pump"}}, limit)

    made, data, dropped = make(path, drives, counts(), None, extra, 10**6)
    assert (data, dropped) == afresh(10**6)
    settings.save([SettingRow("d2", 100, 0, "1-00", 1, "1", 50.0, 1, "1", 50.0, "sweep")])
    again, data, dropped = make(path, drives, counts(), made, extra, 10**6)
    assert again.events is made.events  # not read again
    assert (data, dropped) == afresh(10**6)
    history.add([DriveEvent("l1", "d1", "k99", "fault", "7", 7, "", None, None, "seen", "", 99)])
    last, data, dropped = make(path, drives, counts(), again, extra, 2000)
    assert last.settings is again.settings and dropped > 0
    assert (data, dropped) == afresh(2000)
    settings.close()
    history.close()
