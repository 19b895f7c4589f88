"""The drives' own logs, watched unattended through their lines' runners.

Every ``events_every`` each watched drive's log is asked what its document
says shows a change - its change counter (SINAMICS r0944), or its newest
entry (Danfoss 15-30..15-32) - by background jobs of its line, which never go
ahead of a due poll (:class:`~pkwbus.master.planning.jobs.Priority`). Only
when that changed, at start, and whenever the drive or its line comes back
(a power cycle, an outage, a lost port) is the whole log swept
(:mod:`pkwbus.protocol.logs`) and each entry stored once in the history
database (:mod:`.store`): what was logged while pkwbus, its host or its line
was down is found then. Each new entry is a log line and a step of
``pkwbus_drive_events_total``.

Time: an entry's wall-clock ``time`` comes from the drive's own time base.
A SINAMICS or MICROMASTER 4 entry is in the runtime base (r2114), read in the
same sweep, so its time is when the sweep read r2114 minus the runtime since
the entry; exact while the drive stayed powered since the entry. Neither
runtime counts while the drive is off: SINAMICS's starts again from 0 at
power-up (an entry whose runtime is ahead of the runtime now was logged before
it, and only ``seen`` is known), MICROMASTER 4's goes on from where it stood
(so an entry from before the drive was off looks younger by the time it was
off). Whichever, a drive whose runtime went on less than the wall clock since
the last sweep (beyond :data:`OFF_SLACK` and :data:`OFF_DRIFT`) was off
meanwhile, at a time not known: the entries that came since that sweep get
``seen``. Where the log has no time base that a document explains (Danfoss
15-32), ``time_source`` is ``seen``. An entry timed by its age (a PROFIdrive
P948 of Unsigned16) is placed when the drive answered the read of its age,
minus the age, and known again by where it placed (:mod:`.ages`).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from pkwbus.catalog.alarms import CodeTable
from pkwbus.catalog.description import ParameterDescription
from pkwbus.errors import PkwbusError
from pkwbus.master.events import Event, LineState
from pkwbus.master.planning.jobs import Job, JobKind, JobResult, Priority
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.master.planning.plan import HealthChanged
from pkwbus.protocol import pkw
from pkwbus.protocol.logs import (
    Age,
    DriveLog,
    LogEntry,
    NoSuchLog,
    Opaque,
    Read,
    Runtime,
    SweepResult,
)
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.service.history.ages import AgedKeys
from pkwbus.service.history.store import DriveEvent, HistoryError
from pkwbus.service.history.stream import EVENT_LABELS, EventStream
from pkwbus.service.runtime import LineTask
from pkwbus.waiting import wait_event

__all__ = [
    "EVENT_LABELS",
    "OFF_DRIFT",
    "OFF_SLACK",
    "LogWatcher",
    "Watched",
    "entry_key",
    "was_off",
]

log = logging.getLogger("pkwbus.service.history")

SWEEP_TRIES = 3  # a log that changes while it is read is read again, this many times
PRUNE_EVERY = 3600.0  # seconds between two prunings of a drive's old entries
# A log whose sweeps read only what came since (the SINAMICS alarm buffer) is read whole
# by its first sweep this long after the last whole one, and after the drive or its line
# came back; only a whole read says what the drive no longer holds (pruning).
WHOLE_EVERY = 3600.0
# A drive was off since the last sweep when its runtime went on less than the wall clock by
# more than this (seconds: a runtime counted in whole seconds, MICROMASTER 4's r2114, and
# the time an answer takes) and this share of the time between (its clock against ours).
OFF_SLACK = 2.0
OFF_DRIFT = 0.001


@dataclass
class Watched:
    """A drive whose log is watched: its line, its log, how its codes read in words."""

    line: str
    drive: str
    dialect: Dialect
    log: DriveLog
    every: float
    codes: CodeTable | None = None
    # Sweep at the next watch: at start, and when the drive or its line comes back.
    due_sweep: bool = True
    last_watch: tuple[int | None, ...] | None = None
    last_sweep: SweepResult | None = None  # what the last sweep found, for the next one
    whole_at: float | None = None  # when the log was last read whole
    # When the last sweep read the drive's runtime, and what it read (None: not yet).
    anchor: tuple[float, Runtime] | None = None
    pruned: float = 0.0
    aged: AgedKeys | None = None  # the entries timed by their age kept (:mod:`.ages`)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    answered: dict[Read, float] = field(default_factory=dict)  # the last round's answer times


class _Unanswered(PkwbusError):
    """A read of the round got no answer (timeout, line down): the round is tried later."""


def entry_key(entry: LogEntry) -> str:
    """An entry's identity: its content, never its place in the log."""
    when = entry.drive_time
    stamp = (
        f"runtime:{when.ms}"
        if isinstance(when, Runtime)
        else f"raw:{when.raw}"
        if isinstance(when, Opaque)
        else ""
    )
    value = "" if entry.value is None else str(entry.value)
    return f"{entry.kind.value}|{entry.code}|{value}|{stamp}"


def _as_int(read: Read, response: pkw.PkwResponse) -> int | None:
    if read.element:  # a description element: a number
        return response.raw if isinstance(response, pkw.DescriptionResponse) else None
    if not isinstance(response, pkw.ValueResponse):
        return None
    raw, bits = response.raw, response.width.value
    if read.signed and raw >> (bits - 1):
        raw -= 1 << bits
    return raw


class LogWatcher:
    """Watches the logs of ``watched`` through the lines' runners; an observer of the lines'
    events, to sweep again whatever comes back."""

    def __init__(
        self,
        runners: dict[str, LineTask],
        stream: EventStream,
        watched: Sequence[Watched],
        *,
        retention: float,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.runners = runners
        self.stream = stream
        self.store = stream.store
        self.watched = list(watched)
        self.retention = retention
        self.clock = clock
        self._tasks: list[asyncio.Task[None]] = []

    # ------------------------------------------------------------ the service's

    async def start(self) -> None:
        """Count what the history already holds, then watch every drive."""
        kinds = [(w.line, w.drive, kind.value) for w in self.watched for kind in w.log.kinds]
        if not await self.stream.start(kinds):
            return
        for w in self.watched:
            name = f"{w.log.name} of {w.drive}"
            self._tasks.append(asyncio.create_task(self._watch(w), name=name))

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()

    def on_events(self, events: Sequence[Event]) -> None:
        """A drive back up, or its line's port open again: its log is swept at once."""
        for event in events:
            if isinstance(event, HealthChanged) and event.up:
                self._again([w for w in self.watched if w.drive == event.drive])
            elif isinstance(event, LineState) and event.up:
                self._again([w for w in self.watched if w.line == event.line])

    def _again(self, which: list[Watched]) -> None:
        for w in which:
            w.due_sweep = True
            w.whole_at = None  # read whole: a power cycle may have rearranged it
            w.wake.set()

    # ------------------------------------------------------------ one drive

    async def _watch(self, w: Watched) -> None:
        while True:
            try:
                await self._look(w)
            except _Unanswered:
                pass  # tried again at the next watch
            except (_Refused, NoSuchLog) as exc:
                log.warning(
                    "drive %s: its %s is not watched: %s", w.drive, w.log.name, exc,
                    extra={"line": w.line, "drive": w.drive},
                )  # fmt: skip
                return
            except HistoryError as exc:
                log.error("drive %s: %s", w.drive, exc, extra={"line": w.line, "drive": w.drive})
            w.wake.clear()
            await wait_event(w.wake, w.every)

    async def _look(self, w: Watched) -> None:
        reads = w.log.watch()
        values = await self._round(w, reads)
        if all(v is None for v in values.values()):
            raise _Refused(f"the drive refuses {_names(reads)}")
        now = tuple(values[r] for r in reads)
        if now == w.last_watch and not w.due_sweep:
            return
        w.due_sweep = True  # until a sweep succeeds
        for _ in range(SWEEP_TRIES):
            if await self._sweep(w):
                w.due_sweep = False
                w.last_watch = now
                return
        log.info(
            "drive %s: its %s changed while it was read, %d times: read again later",
            w.drive, w.log.name, SWEEP_TRIES, extra={"line": w.line, "drive": w.drive},
        )  # fmt: skip

    async def _sweep(self, w: Watched) -> bool:
        read_at = self.clock()
        whole = w.whole_at is None or read_at - w.whole_at >= WHOLE_EVERY
        sweep = w.log.sweep(None if whole else w.last_sweep)
        answered: dict[Read, float] = {}  # when each read of the sweep was answered
        while reads := sweep.next():
            sweep.feed(await self._round(w, reads))
            answered.update(w.answered)
            for r in w.log.runtime[:1]:  # when the drive's runtime now was answered
                read_at = w.answered.get(r, read_at)
        found = sweep.result()
        if found is None:
            return False
        before = set(w.last_sweep.entries) if w.last_sweep is not None else set()
        off = was_off(w.anchor, read_at, found.runtime)  # since the last sweep
        w.last_sweep = found
        if found.runtime is not None:
            w.anchor = (read_at, found.runtime)
        seen = self.clock()
        if whole:
            w.whole_at = read_at
        events = [
            self._event(w, e, found.runtime if not off or e in before else None, read_at, seen)
            for e in found.entries
        ]
        if any(isinstance(e.drive_time, Age) for e in found.entries):
            if w.aged is None:
                w.aged = AgedKeys(await asyncio.to_thread(self.store.known, w.drive))
            events = w.aged.place(found.entries, events, answered)
        new = await self.stream.record(events)
        for e in reversed(new):  # the oldest first
            self._tell(e)
        if whole and seen - w.pruned >= PRUNE_EVERY:
            w.pruned = seen
            held = [e.key for e in events]
            # A setting's change is held by no log: it goes once older than the retention.
            kinds = [*(k.value for k in w.log.kinds), "setting"]
            cutoff = seen - self.retention
            await asyncio.to_thread(self.store.prune, w.drive, kinds, held, cutoff)
        return True

    def _event(
        self, w: Watched, entry: LogEntry, runtime: Runtime | None, read_at: float, seen: float
    ) -> DriveEvent:
        when, source = None, "seen"
        stamp = entry.drive_time
        if isinstance(stamp, Runtime) and runtime is not None and stamp <= runtime:
            when, source = read_at - (runtime.ms - stamp.ms) / 1000, "runtime"
        code, text = str(entry.code), ""
        if w.codes is not None:
            (alarm,) = w.codes.decode(entry.code) or (None,)
            if alarm is not None:
                code, text = alarm.code, alarm.text
        return DriveEvent(
            w.line, w.drive, entry_key(entry), entry.kind.value, code, entry.code, text,
            entry.value, when, source, "" if stamp is None else str(stamp), seen,
        )  # fmt: skip

    def _answered(self, times: dict[Read, float], read: Read, _: object) -> None:
        times.setdefault(read, self.clock())

    def _tell(self, e: DriveEvent) -> None:
        at = time.strftime("%Y-%m-%d %H:%M:%S %z", time.localtime(e.when))
        shown = f"{e.code} {e.text}".strip()
        value = "" if e.value is None else f", value {e.value}"
        log.warning(
            "drive %s logged %s %s%s at %s (%s)", e.drive, e.kind, shown, value, at,
            "by its runtime" if e.time_source == "runtime" else "when pkwbus first read it",
            extra={"line": e.line, "drive": e.drive},
        )  # fmt: skip

    async def _round(self, w: Watched, reads: Sequence[Read]) -> dict[Read, int | None]:
        """The values of ``reads``, by background jobs of the drive's line; None for a value
        the drive refused. :class:`_Unanswered` when one got no answer. When each answer
        came is in ``w.answered``."""
        runner = self.runners.get(w.line)
        if runner is None:
            raise _Unanswered()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + max(w.every, 30.0)
        futures: list[asyncio.Future[JobResult]] = []
        answered = w.answered = {}
        for r in reads:
            future: asyncio.Future[JobResult] = loop.create_future()
            future.add_done_callback(functools.partial(self._answered, answered, r))
            if r.element:
                request = pkw.read_description(w.dialect, r.pnu, r.element)
            else:
                request = pkw.read(w.dialect, r.pnu, r.index)
            runner.submit(Job(w.drive, request, JobKind.READ, Priority.BACKGROUND, deadline,
                              ParameterDescription(), future))  # fmt: skip
            futures.append(future)
        values: dict[Read, int | None] = {}
        for r, future in zip(reads, futures, strict=True):
            outcome = (await future).outcome
            if isinstance(outcome, Answered):
                values[r] = _as_int(r, outcome.response)
            elif isinstance(outcome, Rejected):
                values[r] = None
            else:
                for other in futures:
                    other.cancel()
                raise _Unanswered()
        return values


def was_off(anchor: tuple[float, Runtime] | None, read_at: float, runtime: Runtime | None) -> bool:
    """Whether the drive was off between ``anchor`` (when the last sweep read its runtime,
    and what it read) and ``read_at``, when it read ``runtime``: its runtime went on less
    than the wall clock (a SINAMICS runtime restarted, a MICROMASTER 4 counter stood still)."""
    if anchor is None or runtime is None:
        return False
    then, counted = anchor
    wall = read_at - then
    return wall - (runtime.ms - counted.ms) / 1000 > OFF_SLACK + OFF_DRIFT * wall


class _Refused(PkwbusError):
    """The drive refuses what its log's watch reads: it has no such log."""


def _names(reads: Sequence[Read]) -> str:
    return ", ".join(f"{r.pnu}[{r.index}]" if r.index else str(r.pnu) for r in reads)
