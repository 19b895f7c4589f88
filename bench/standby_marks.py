"""Hot standby: what a held line's drive-memory marks cost per turn while nothing changes,
and per turn after a change (service.assembly.line_marks, written every 2 s per held line).

One line of ``--drives`` drives (126) whose history database keeps ``--entries`` log
entries (10,000) and ``--settings`` swept settings per drive (20, baselines included), a
describe book of ``--models`` drive models (3) with ``--pnus`` parameters each (300), no
drive in maintenance; a fake etcd (in memory). Two writers of the same line, in one run:

- ``every turn``: without counts of what changed (the path taken where a source counts
  nothing; how every turn went before the counts): every turn reads the line's entries
  and settings from SQLite, makes the describe book JSON and encodes the document (in a
  thread, the book copied on the loop), only to compare it with the last one put;
- ``on change``: with the history's change counts and the book keeper's saves.

Printed per writer: CPU per idle turn (``time.process_time``, all threads) and the loop
thread's share of it (``time.thread_time`` on the loop), the median of ``--repeat`` runs
of ``--turns`` turns; then, for the ``on change`` writer, CPU per turn after one change of
each kind before each turn: a setting read by a sweep (its ``seen`` moves: with sweeps on,
most turns), a new log entry, a drive put in maintenance or out, a describe-book save;
and the document's size.

    .venv/bin/python -m bench.standby_marks [--drives 126] [--entries 10000] [--turns 50]
        [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from bench._measure import markdown_table
from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.service.assembly.line_marks import MARK, LineMarks
from pkwbus.service.history.settings_store import SettingRow, SettingsStore
from pkwbus.service.history.store import DriveEvent, HistoryStore


class FakeMarks:
    """etcd's marks, in memory."""

    def __init__(self) -> None:
        self.kept: dict[tuple[str, str], bytes] = {}
        self.puts = 0

    async def get(self, line: str, name: str) -> bytes | None:
        return self.kept.get((line, name))

    async def put(self, line: str, name: str, value: bytes) -> bool:
        self.puts += 1
        self.kept[(line, name)] = value
        return True


class Keeper:
    """The describe book's keeper as the marks see it: it counts its saves."""

    def __init__(self, book: DescriptionBook) -> None:
        self.book = book
        self.saves = 0

    def save(self) -> None:
        self.saves += 1


def fill(folder: Path, drives: list[str], entries: int, settings: int) -> HistoryStore:
    store = HistoryStore(folder / "history.sqlite")
    store.add([logged(drives[i % len(drives)], i) for i in range(entries)])
    kept = SettingsStore(store.path, store.changes)
    for drive in drives:
        kept.save([row(drive, pnu, 1.7e9) for pnu in range(settings)])
        kept.swept(drive, "FC-302 V4.42", 1.7e9)
    kept.close()
    return store


def logged(drive: str, i: int) -> DriveEvent:
    """A log entry as a SINAMICS drive's fault buffer gives them, timed by its runtime."""
    return DriveEvent("l1", drive, f"fault|{i}|{i % 7}|runtime:{i * 1000}", "fault",
                      f"A{i % 90:05d}", i % 90, "Overcurrent at acceleration", i % 300,
                      1.7e9 + i, "runtime", f"runtime:{i * 1000}", 1.7e9 + i)  # fmt: skip


def row(drive: str, pnu: int, when: float) -> SettingRow:
    return SettingRow(drive, 100 + pnu, 0, f"{pnu // 100}-{pnu % 100:02d}", 50, '"50"', when,
                      50, '"50"', when, "sweep")  # fmt: skip


def book_of(models: int, pnus: int) -> DescriptionBook:
    book = DescriptionBook()
    for m in range(models):
        for pnu in range(pnus):
            described = DriveDescription(type_code=6, conversion=-1, unit="Hz",
                                         name=f"PARAMETER {pnu}", read_only=False)  # fmt: skip
            book.put(f"FC:30{m}:4.42", 100 + pnu, described, [1, 2, 3, 4, 5, 6])
    return book


async def turns(marks: LineMarks, n: int, change: Any = None) -> tuple[float, float]:
    """CPU seconds per turn: the process's, and the loop thread's."""
    cpu, loop_cpu = time.process_time(), time.thread_time()
    for _ in range(n):
        if change is not None:
            change()
        await marks.write("l1")
    return (time.process_time() - cpu) / n, (time.thread_time() - loop_cpu) / n


async def measure(args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    drives = [f"d{i:03d}" for i in range(args.drives)]
    store = fill(folder, drives, args.entries, args.settings)
    book = book_of(args.models, args.pnus)
    keeper = Keeper(book)
    runtime = SimpleNamespace(snapshot=SimpleNamespace(maintenance={}), runners={})
    fake = FakeMarks()

    def make(counted: bool) -> LineMarks:
        return LineMarks(fake, runtime, store.path, lambda line: drives, book=book,  # type: ignore[arg-type]
                         saved=keeper if counted else None,
                         changes=store.changes if counted else None)  # fmt: skip

    writers = {"every turn": make(False), "on change": make(True)}
    idle: dict[str, list[tuple[float, float]]] = {name: [] for name in writers}
    for marks in writers.values():
        await marks.write("l1")  # the first turn makes and puts them
    for _ in range(args.repeat):
        for name, marks in writers.items():  # side by side, in turn
            idle[name].append(await turns(marks, args.turns))
    settings = SettingsStore(store.path, store.changes)
    step = iter(range(1, 10**9))

    def sweep_read() -> None:  # one setting read again by a sweep: its `seen` moves
        settings.save([row(drives[next(step) % len(drives)], 0, 1.8e9 + next(step))])

    def log_entry() -> None:
        i = args.entries + next(step)
        store.add([logged(drives[i % len(drives)], i)])

    def maintenance() -> None:
        if runtime.snapshot.maintenance:
            runtime.snapshot.maintenance.clear()
        else:
            runtime.snapshot.maintenance[drives[0]] = SimpleNamespace(reason="bearing")

    def book_save() -> None:
        described = DriveDescription(type_code=6, name=f"NEW {next(step)}")
        book.put("FC:302:4.42", 5000, described, [1, 2])
        keeper.save()

    kinds = {"a setting read": sweep_read, "a new log entry": log_entry,
             "a maintenance switch": maintenance, "a book save": book_save}  # fmt: skip
    n = max(3, args.turns // 5)
    changed = {kind: [await turns(writers["on change"], n, change) for _ in range(args.repeat)]
               for kind, change in kinds.items()}  # fmt: skip
    settings.close()
    store.close()
    size = len(fake.kept[("l1", MARK)])
    runs = [(name, "idle", idle[name]) for name in writers]
    runs += [("on change", f"after {kind}", got) for kind, got in changed.items()]
    cpu = [statistics.median(c for c, _ in got) * 1e3 for _, _, got in runs]
    loop = [statistics.median(c for _, c in got) * 1e3 for _, _, got in runs]
    rows = [
        {"writer": name, "turn": turn, "CPU ms/turn": c, "of it on the loop, ms": on_loop}
        for (name, turn, _), c, on_loop in zip(runs, cpu, loop, strict=True)
    ]
    before, after = cpu[0], cpu[1]
    return {"rows": rows, "bytes": size, "ratio": before / after if after > 0 else float("inf")}


def run(
    drives: int = 126, entries: int = 10_000, turns_: int = 50, repeat: int = 3
) -> dict[str, Any]:
    args = argparse.Namespace(drives=drives, entries=entries, settings=20, models=3, pnus=300,
                              turns=turns_, repeat=repeat)  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        return asyncio.run(measure(args, Path(folder)))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=126)
    parser.add_argument("--entries", type=int, default=10_000)
    parser.add_argument("--settings", type=int, default=20)
    parser.add_argument("--models", type=int, default=3)
    parser.add_argument("--pnus", type=int, default=300)
    parser.add_argument("--turns", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        result = asyncio.run(measure(args, Path(folder)))
    print(f"one line, {args.drives} drives, {args.entries} log entries, {args.settings}"
          f" settings a drive, a book of {args.models}x{args.pnus}: a document of"
          f" {result['bytes']:,} bytes")  # fmt: skip
    print(markdown_table(result["rows"], digits=3))
    print(f"idle turn: {result['ratio']:.0f}x less CPU with the change counts")
    return 0


if __name__ == "__main__":
    sys.exit(main())
