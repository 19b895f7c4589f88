"""The settings watcher's promise over any run of events, drawn by Hypothesis: each change
nobody audited is told once (one event, whatever the sweeps, restarts or failures of the
history around it), never a write pkwbus made (answered, or found by a sweep after its
answer got lost), and a setting is flagged exactly while it differs from its baseline.

The model is the issue's rule, kept apart from the code: the baseline is the first value
read, moved by pkwbus's writes and by an accepted baseline; a value read that differs
from the baseline and from the value read before it is a new change."""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule
from prometheus_client import CollectorRegistry

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.target import DriveTarget
from pkwbus.protocol.values import ParameterRef, Scaling, ValueType
from pkwbus.service.history.setting_reads import Swept
from pkwbus.service.history.settings import KIND, SettingsWatcher
from pkwbus.service.history.settings_store import SettingsStore
from pkwbus.service.history.store import HistoryError, HistoryStore
from pkwbus.service.history.stream import EventStream
from pkwbus.service.runtime import DriveEntry

RAMP = ParameterRef(341, None, "3-41")
FMT = ParameterDescription("Ramp 1 Ramp Up Time", ValueType.U32, Scaling.conversion(-2), "s")
VALUES = st.integers(1, 6)  # few values: repeats, returns to the baseline, changes back


class Flaky(SettingsStore):
    fail = False

    def save(self, rows: Any, events: Any = ()) -> Any:
        if self.fail:
            raise HistoryError("history database: disk I/O error")
        return super().save(rows, events)


class SettingsRun(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.loop = asyncio.new_event_loop()
        self.folder = Path(tempfile.mkdtemp(prefix="pkwbus-settings-"))
        self.history = HistoryStore(self.folder / "history.sqlite")
        self.clock = 1000.0
        self.drive = 1  # the value the drive holds
        # The model.
        self.baseline: int | None = None
        self.read: int | None = None  # the value last read and kept
        self.expected: int | None = None  # a write whose answer got lost
        self.events: list[int] = []
        self._start()

    def _start(self) -> None:
        self.store = Flaky(self.folder / "history.sqlite")
        registry = CollectorRegistry()
        entry = DriveEntry("fan", "l1", DriveTarget.create("fc", 1))
        self.s = Swept("l1", entry, 60.0, [RAMP], "danfoss-fc")
        self.w = SettingsWatcher(
            {}, self.store, EventStream(self.history, registry), [self.s], registry,
            clock=self._now,
        )  # fmt: skip
        kept = self.store.load("fan")
        self.s.rows = kept.rows or {}
        self.s.loaded = True
        self.w._show(self.s)
        self.expected = None  # pkwbus's memory of a lost answer goes with it

    def _now(self) -> float:
        self.clock += 1.0
        return self.clock

    def _run(self, coroutine: Any) -> Any:
        return self.loop.run_until_complete(coroutine)

    # ------------------------------------------------------------ what happens

    @rule(value=VALUES)
    def keypad(self, value: int) -> None:
        self.drive = value

    @rule(fails=st.booleans())
    def sweep(self, fails: bool) -> None:
        self.store.fail = fails
        try:
            self._run(self.w._compare(self.s, RAMP, FMT, self.drive, self.drive / 100))
        except HistoryError:
            assert fails
            return
        finally:
            self.store.fail = False
        value = self.drive
        if self.baseline is None or self.expected == value:
            self.baseline = value
        elif value != self.baseline and value != self.read:
            self.events.append(value)
        self.read, self.expected = value, None

    @rule(value=VALUES, fails=st.booleans())
    def audited_write(self, value: int, fails: bool) -> None:
        self.drive = value
        self.store.fail = fails
        self._run(self.w.written("fan", 341, 0, value, value / 100))  # never raises
        self.store.fail = False
        if self.read is not None:
            self.baseline = self.read = value
            self.expected = value if fails else None
        else:
            self.expected = value

    @rule(value=VALUES, applied=st.booleans())
    def write_without_answer(self, value: int, applied: bool) -> None:
        if applied:
            self.drive = value
        self._run(self.w.written("fan", 341, 0, value, value / 100, answered=False))
        self.expected = value

    @rule()
    def accept(self) -> None:
        self._run(self.w.accept("fan"))
        if self.read is not None:
            self.baseline = self.read

    @rule()
    def restart(self) -> None:
        self.store.close()
        self._start()
        if self.baseline is not None and self.read is not None:
            kept = self.s.rows[(341, 0)]
            # What the store kept is what the model says, a failed write's memory aside.
            self.baseline, self.read = kept.baseline_raw, kept.raw

    # ------------------------------------------------------------ what must hold

    @invariant()
    def each_change_told_once(self) -> None:
        told = [e.value for e in reversed(self.history.latest(drive="fan")) if e.kind == KIND]
        assert told == self.events

    @invariant()
    def flagged_exactly_while_it_differs(self) -> None:
        row = self.s.rows.get((341, 0))
        differs = row is not None and row.raw is not None and row.raw != row.baseline_raw
        shown = [s for f in self.w.changed.collect() for s in f.samples]
        assert bool(shown) == differs == (row is not None and row.changed_seen is not None)
        if row is not None and self.read is not None:
            assert (row.raw, row.baseline_raw) == (self.read, self.baseline)

    def teardown(self) -> None:
        self.store.close()
        self.history.close()
        self.loop.close()
        shutil.rmtree(self.folder, ignore_errors=True)


SettingsRun.TestCase.settings = settings(max_examples=60, stateful_step_count=30)
test_settings_run = SettingsRun.TestCase
