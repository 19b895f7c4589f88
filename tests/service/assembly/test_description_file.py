"""The drives' descriptions are written off the event loop: by a thread of its own, one write
at a time, the latest save winning, never half a file; a stop waits for a write under way."""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path

from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.service.assembly.description_file import DescriptionFile


class Gated(DescriptionFile):
    """Each write waits for ``gate``; the threads and texts that wrote are kept."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self.gate = threading.Event()
        self.gate.set()
        self.writing = threading.Event()
        self.writers: list[int] = []
        self.texts: list[str] = []

    def _write(self, text: str) -> None:
        self.writing.set()
        assert self.gate.wait(30)
        self.writers.append(threading.get_ident())
        self.texts.append(text)
        super()._write(text)


def describe(kept: DescriptionFile, identity: str, pnus: range, conversion: int = -2) -> None:
    for pnu in pnus:
        kept.book.put(identity, pnu, DriveDescription(type_code=4, conversion=conversion), (1, 2))


def on_disk(path: Path) -> object:
    return json.loads(path.read_text(encoding="utf-8"))


async def test_a_save_on_the_loop_is_written_by_another_thread(tmp_path: Path) -> None:
    path = tmp_path / "var" / "audit.sqlite.descriptions.json"
    kept = Gated(path)
    describe(kept, "fc:FC-102|05.11", range(1600, 1610))
    kept.save()
    await kept.settled()
    assert kept.writers and threading.get_ident() not in kept.writers
    assert on_disk(path) == kept.book.to_json()
    assert DescriptionFile(path).book.entries == kept.book.entries  # read back at a restart


async def test_the_latest_save_wins_and_what_is_saved_is_the_book_as_it_was(
    tmp_path: Path,
) -> None:
    path = tmp_path / "descriptions.json"
    kept = Gated(path)
    kept.gate.clear()
    describe(kept, "fc:a", range(1, 2))
    kept.save()  # its write waits at the gate
    assert await asyncio.to_thread(kept.writing.wait, 30)
    for n in range(2, 50):  # saved while it waits: only the last is written after it
        describe(kept, "fc:a", range(n, n + 1))
        kept.save()
    last = kept.book.to_json()
    describe(kept, "fc:b", range(1, 2))  # in the book, never saved: not on disk
    kept.gate.set()
    await kept.settled()
    first, latest = (json.loads(text)["drives"] for text in kept.texts)  # two writes
    assert list(first) == ["fc:a"] and list(first["fc:a"]) == ["1"]
    assert latest == last["drives"] and "fc:b" not in latest
    assert on_disk(path) == last


async def test_a_reader_never_finds_half_a_file(tmp_path: Path) -> None:
    path = tmp_path / "descriptions.json"
    kept = DescriptionFile(path)
    describe(kept, "fc:big", range(3000))  # some 700 kB: a write takes a while
    kept.save()
    await kept.settled()
    stop = threading.Event()
    reads: list[object] = []

    def read() -> None:
        while not stop.is_set():
            data = on_disk(path)  # a half file would raise here
            assert isinstance(data, dict) and data["format"] == 1
            reads.append(data)

    reader = asyncio.create_task(asyncio.to_thread(read))
    try:
        for conversion in range(-4, 4):
            describe(kept, "fc:big", range(3000), conversion)
            kept.save()
            await kept.settled()
    finally:
        stop.set()
        await reader  # raises what the reader found
    assert reads
    assert on_disk(path) == kept.book.to_json()
    assert not path.with_name(path.name + ".new").exists()


async def test_settled_waits_for_a_write_under_way(tmp_path: Path) -> None:
    path = tmp_path / "descriptions.json"
    kept = Gated(path)
    kept.gate.clear()
    describe(kept, "fc:a", range(5))
    kept.save()
    assert await asyncio.to_thread(kept.writing.wait, 30)
    settled = asyncio.create_task(kept.settled())
    await asyncio.sleep(0.2)
    assert not settled.done() and not path.exists()  # it cannot end while the write waits
    kept.gate.set()
    await settled
    assert on_disk(path) == kept.book.to_json()
    await kept.settled()  # nothing under way: at once
    assert kept.flush(0)
