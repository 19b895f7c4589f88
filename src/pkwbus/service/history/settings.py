"""The drives' settings, swept unattended through their lines' runners and compared with
each drive's baseline.

Every ``settings.every`` each drive's settings are read one by one, spread over the
interval, by background jobs of its line, which never go ahead of a due poll
(:class:`~pkwbus.master.planning.jobs.Priority`). Raw numbers are compared, so a value
reads the same whatever scaling the drive describes.

- The first value read of a setting becomes its baseline (the first complete sweep is
  the drive's baseline), kept in the history database (:mod:`.settings_store`).
- A write pkwbus makes (the API, a restore; each audited) moves that setting's baseline
  (:meth:`SettingsWatcher.written`); ``PUT .../settings/baseline`` makes the present values
  the baseline (:meth:`SettingsWatcher.accept`).
- Any other difference is a change nobody audited (the keypad, another master, a
  parameter copy): ``pkwbus_drive_setting_changed`` while it lasts, one log line and one
  event in the stream of the drives' own log entries (:mod:`.stream`), kind ``setting``.
- A drive identified as another model (as the planner reads its identity) starts a new
  baseline, and the log and the stream say so; other software on the same model keeps it.

What the drive says of the factory setting: a Danfoss FC drive's description element 20
(the factory value) and 21 (additional characteristics: no bus access, read-only over
the bus, not while running), read once per run; a PROFIdrive drive's identifier bit 12
("changed from factory setting"), read with each sweep
(:mod:`pkwbus.protocol.pkw.descriptions`). None where the drive gives none.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from prometheus_client import CollectorRegistry, Gauge

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.master.events import Event, LineState
from pkwbus.master.planning.plan import Described
from pkwbus.protocol.values import ParameterRef
from pkwbus.service.history.backup import drive_type
from pkwbus.service.history.setting_reads import SettingReads, Swept, Unanswered
from pkwbus.service.history.settings_store import (
    SettingRow,
    SettingsStore,
    stored_text,
    stored_value,
)
from pkwbus.service.history.settings_view import changed_count, settings_view
from pkwbus.service.history.store import DriveEvent, HistoryError
from pkwbus.service.history.stream import EventStream
from pkwbus.service.runtime import LineTask

__all__ = ["KIND", "SettingsWatcher"]

log = logging.getLogger("pkwbus.service.settings")

KIND = "setting"  # the kind of a setting's change in the stream of the drives' events
NEW_BASELINE = "baseline"  # the code of the event that says a drive starts a new baseline


class SettingsWatcher:
    """Sweeps the settings of ``swept`` through the lines' runners; an observer of the
    lines' events, to start a new baseline for a drive that is another drive."""

    def __init__(
        self,
        runners: dict[str, LineTask],
        store: SettingsStore,
        stream: EventStream,
        swept: Sequence[Swept],
        registry: CollectorRegistry,
        *,
        clock: Callable[[], float] = time.time,
        job_timeout: float = 30.0,
    ) -> None:
        self.runners = runners
        self.reads = SettingReads(runners, job_timeout)
        self.store = store
        self.stream = stream
        self.swept = {s.drive: s for s in swept}
        self.clock = clock
        self.job_timeout = job_timeout
        self._tasks: list[asyncio.Task[None]] = []
        self._identifying: set[asyncio.Future[None]] = set()
        self._lines: dict[str, asyncio.Event] = {}  # each line's port open
        self._told: dict[str, tuple[int, float | None]] = {}  # what the read model shows
        self.changed = Gauge(
            "pkwbus_drive_setting_changed",
            "1 while a setting of the drive differs from its baseline and nobody audited the"
            " change (the keypad, another master, a parameter copy); no series otherwise",
            ["line", "drive", "parameter", "index"],
            registry=registry,
        )
        self.swept_at = Gauge(
            "pkwbus_drive_settings_swept_timestamp_seconds",
            "End of the drive's last complete sweep of its settings",
            ["line", "drive"],
            registry=registry,
        )

    # ------------------------------------------------------------ the service's

    async def start(self) -> None:
        """Load what the history keeps of each drive, then sweep every drive."""
        if not await self.stream.start():
            return
        try:
            for s in self.swept.values():
                kept = await asyncio.to_thread(self.store.load, s.drive)
                s.identity, s.swept, s.rows = kept.identity, kept.swept, kept.rows or {}
                s.loaded = True
                self._show(s)
        except HistoryError as exc:
            log.error("%s: the drives' settings are not swept", exc)
            return
        for s in self.swept.values():
            if s.told is not None:  # identified while its baseline was loaded
                await self._identified(s, s.told)
        for s in self.swept.values():
            self._tasks.append(asyncio.create_task(self._sweeps(s), name=f"settings {s.drive}"))

    async def stop(self) -> None:
        for task in [*self._tasks, *self._identifying]:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()

    def _up(self, line: str) -> asyncio.Event:
        return self._lines.setdefault(line, asyncio.Event())

    def line_state(self, line: str, up: bool) -> None:
        """Whether ``line``'s port is open now (a watcher made while the lines run)."""
        event = self._up(line)
        event.set() if up else event.clear()

    def unregister(self, registry: CollectorRegistry) -> None:
        """Its gauges out of ``registry`` (a reload makes another watcher)."""
        for gauge in (self.changed, self.swept_at):
            registry.unregister(gauge)

    def on_events(self, events: Sequence[Event]) -> None:
        """A drive identified as another drive starts a new baseline; a line's port open
        or closed (the reads wait for it)."""
        for event in events:
            if isinstance(event, LineState):
                up = self._up(event.line)
                up.set() if event.up else up.clear()
            if isinstance(event, Described) and event.identity is not None:
                s = self.swept.get(event.drive)
                if s is None or event.identity == s.told:
                    continue
                s.told = event.identity
                if s.loaded:  # else compared once its baseline is loaded
                    task = asyncio.ensure_future(self._identified(s, event.identity))
                    self._identifying.add(task)
                    task.add_done_callback(self._identifying.discard)

    async def _identified(self, s: Swept, identity: str) -> None:
        if s.identity == identity:
            return
        before, s.identity = s.identity, identity
        try:
            # The first identity known of it, or the same model with other software (an
            # update keeps what was set): its baseline's.
            if before is None or drive_type(before) == drive_type(identity):
                await asyncio.to_thread(self.store.swept, s.drive, identity, s.swept)
                return
            for row in s.rows.values():  # what the old drive held is gone at once
                self._unflag(s, row)
            s.rows, s.swept = {}, None
            self._tell(s)
            s.factory.clear()
            s.characteristics.clear()
            s.from_factory.clear()
            with contextlib.suppress(KeyError):
                self.swept_at.remove(s.line, s.drive)
            await asyncio.to_thread(self.store.forget, s.drive, identity)
            log.warning(
                "drive %s is another drive now (%s, was %s): its settings start a new"
                " baseline", s.drive, identity, before, extra={"line": s.line, "drive": s.drive},
            )  # fmt: skip
            now = self.clock()
            await self.stream.record([DriveEvent(
                s.line, s.drive, f"{KIND}|{NEW_BASELINE}|{identity}|{now:.3f}", KIND,
                NEW_BASELINE, 0, "another drive: a new baseline", None, None, "seen", "", now,
            )])  # fmt: skip
        except HistoryError as exc:
            log.error("drive %s: %s", s.drive, exc, extra={"line": s.line, "drive": s.drive})

    # ------------------------------------------------------------ what people do

    async def written(
        self, drive: str, pnu: int, index: int, raw: int, value: Value | None, *,
        answered: bool = True,
    ) -> None:  # fmt: skip
        """pkwbus wrote ``raw`` to a setting (audited): its baseline now. ``answered``
        false: the write got no answer and may have been made: a sweep that reads ``raw``
        there takes it as pkwbus's. Never raises: the history's trouble is logged (the write
        is done; the baseline then moves at the next sweep that reads it)."""
        s = self.swept.get(drive)
        if s is None:
            return
        key = (pnu, index)
        s.expected[key] = raw
        row = s.rows.get(key)
        if not answered or row is None:
            return
        now = self.clock()
        text = stored_text(value)
        moved = replace(row, raw=raw, value=text, seen=now, baseline_raw=raw,
                        baseline_value=text, baseline_since=now, baseline_by="write",
                        changed_seen=None)  # fmt: skip
        s.rows[key] = moved
        if row.changed_seen is not None:
            with contextlib.suppress(KeyError):
                self.changed.remove(s.line, s.drive, row.parameter, str(row.index))
            self._tell(s)
        try:
            await self.store.saved([moved])
            s.expected.pop(key, None)
        except HistoryError as exc:
            log.error("drive %s: the baseline of %s is not stored: %s", drive, row.parameter,
                      exc, extra={"line": s.line, "drive": drive})  # fmt: skip

    async def accept(self, drive: str) -> int:
        """The values last read become ``drive``'s baseline; how many settings that was."""
        s = self.swept[drive]
        now = self.clock()
        rows = [
            replace(r, baseline_raw=r.raw, baseline_value=r.value, baseline_since=now,
                    baseline_by="accepted", changed_seen=None)
            for r in s.rows.values() if r.raw is not None
        ]  # fmt: skip
        await self.store.saved(rows)  # HistoryError
        for row in rows:
            self._unflag(s, s.rows[row.key])
            s.rows[row.key] = row
        self._tell(s)
        return len(rows)

    def view(self, drive: str) -> dict[str, Any]:
        """The last sweep of ``drive``, as the API shows it (times in seconds since the
        epoch)."""
        return settings_view(self.swept[drive])

    # ------------------------------------------------------------ one drive

    async def _sweeps(self, s: Swept) -> None:
        loop = asyncio.get_running_loop()
        step = s.every / max(1, len(s.refs))
        due = loop.time() + s.offset * step
        while True:
            complete = True
            for ref in s.refs:
                await asyncio.sleep(max(0.0, due - loop.time()))
                await self._up(s.line).wait()  # not into a closed port: read once it opens
                due = max(due, loop.time() - step) + step  # late (no answer): no catch-up
                try:
                    await self._one(s, ref)
                except Unanswered:
                    complete = False
                except HistoryError as exc:
                    complete = False
                    log.error("drive %s: %s", s.drive, exc,
                              extra={"line": s.line, "drive": s.drive})  # fmt: skip
            if complete and s.refs:
                s.swept = self.clock()
                s.completed += 1
                self._show(s)
                with contextlib.suppress(HistoryError):
                    await asyncio.to_thread(self.store.swept, s.drive, s.identity, s.swept)
            if not s.refs:
                return

    async def _one(self, s: Swept, ref: ParameterRef) -> None:
        """Read one setting, compare it with its baseline."""
        found = await self.reads.read(s, ref)
        if found is not None:
            await self._compare(s, ref, s.format_of(ref), *found)

    async def _compare(
        self, s: Swept, ref: ParameterRef, fmt: ParameterDescription, raw: int, value: Value
    ) -> None:
        """Compare a value read with its baseline. The row and its event are stored first,
        in one transaction a stop does not cut in two; only then does the change count,
        show and get its log line: a store that fails leaves all as it was, and the next
        sweep tries again (HistoryError)."""
        now = self.clock()
        key = (ref.pnu, ref.index or 0)
        found = s.rows.get(key)
        kept = found or SettingRow(s.drive, ref.pnu, ref.index or 0, ref.name)
        row = replace(kept, raw=raw, value=stored_text(value), seen=now)
        events: list[DriveEvent] = []
        written = s.expected.get(key) == raw  # a write pkwbus made whose answer got lost
        back = changed = False
        if row.baseline_raw is None or written:
            row.baseline_raw, row.baseline_value = raw, row.value
            row.baseline_since, row.baseline_by = now, "write" if written else "sweep"
            back, row.changed_seen = row.changed_seen is not None, None
        elif raw == row.baseline_raw:
            back, row.changed_seen = row.changed_seen is not None, None
        elif raw != kept.raw:  # a change nobody audited (another one, if it was changed)
            row.changed_seen = row.changed_seen or now
            changed = True
            events.append(DriveEvent(
                s.line, s.drive, f"{KIND}|{ref.name}|{ref.index or 0}|{raw}|{now:.3f}", KIND,
                ref.name, ref.pnu, fmt.name, raw, None, "seen", "", now,
            ))  # fmt: skip
        new = await self.store.saved([row], events)
        self.stream.count(new)
        moved = s.rows.get(key)
        if moved is not found:  # a write pkwbus made meanwhile (written): newer than this read
            if moved is not None:
                await self.store.saved([moved])
            return
        s.rows[key] = row
        s.expected.pop(key, None)
        labels = (s.line, s.drive, row.parameter, str(row.index))
        ctx = {"line": s.line, "drive": s.drive}
        if back:
            with contextlib.suppress(KeyError):
                self.changed.remove(*labels)
            if not written:
                log.info("drive %s: setting %s %s is back at its baseline %s", s.drive,
                         ref.name, fmt.name, _said(value, fmt), extra=ctx)  # fmt: skip
        if changed:
            self.changed.labels(*labels).set(1)
            log.warning(
                "drive %s: setting %s %s changed to %s (baseline %s), not by pkwbus",
                s.drive, ref.name, fmt.name, _said(value, fmt),
                _said(stored_value(row.baseline_value), fmt), extra=ctx,
            )  # fmt: skip
        if back or changed:
            self._tell(s)

    def _unflag(self, s: Swept, row: SettingRow) -> None:
        if row.changed_seen is not None:
            row.changed_seen = None
            with contextlib.suppress(KeyError):
                self.changed.remove(s.line, s.drive, row.parameter, str(row.index))

    def _show(self, s: Swept) -> None:
        if s.swept is not None:
            self.swept_at.labels(s.line, s.drive).set(s.swept)
        swept = {(ref.pnu, ref.index or 0) for ref in s.refs}  # not one no longer swept
        for row in s.rows.values():
            if row.changed_seen is not None and row.key in swept:
                self.changed.labels(s.line, s.drive, row.parameter, str(row.index)).set(1)
        self._tell(s)

    def _tell(self, s: Swept) -> None:
        """What the sweep found of the drive now, into the read model (its line's runner),
        when it differs from what was told."""
        seen = (changed_count(s), s.swept)
        runner = self.runners.get(s.line)
        if runner is not None and self._told.get(s.drive) != seen:
            self._told[s.drive] = seen
            runner.settings_seen(s.drive, *seen)


def _said(value: Value | None, fmt: ParameterDescription) -> str:
    if value is None:
        return "?"
    option = fmt.option(value)
    unit = f" {fmt.unit}" if fmt.unit else ""
    return f"{value}{unit}" + (f" ({option})" if option else "")
