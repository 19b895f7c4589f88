"""What a line's events mean for the snapshot and the job's caller: the snapshot's one writer.

A finished job or poll is decoded here (the value in the drive's notation,
or why there is none), the snapshot keeps only values a drive sent, and what
the writer makes of the stream goes back on it as events of its own
(:class:`~pkwbus.master.events.JobDone`, :class:`~pkwbus.master.events.ValueLanded`,
:class:`~pkwbus.master.events.DescriptionChecked`) for the line's observers.
Drive health, status words, the line's port and the DP slaves' states and
diagnoses land in the snapshot here too.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Collection, Sequence
from dataclasses import replace
from functools import partial
from typing import Any

from pkwbus.catalog.precedence import resolve
from pkwbus.master import snapshot_states as states
from pkwbus.master import told
from pkwbus.master.alarms import LineAlarms
from pkwbus.master.decoded import DecodedValues, job_result
from pkwbus.master.events import (
    DescriptionChecked,
    Event,
    Exchanged,
    JobDone,
    ValueLanded,
)
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, JobResult, ProbeJob
from pkwbus.master.planning.outcomes import Answered, Rejected, TimedOut
from pkwbus.master.planning.plan import (
    DescribedAnew,
    DescribedFromBook,
    DescribeTarget,
    DescriptionSettled,
    DriveSpec,
    Finished,
    Forgotten,
    HealthChanged,
    LeftUnanswered,
    PkwLengthTold,
    PollSpec,
    Redecoded,
)
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import (
    Decoding,
    DriveCounts,
    DriveState,
    LineTotals,
    ReadingKey,
    Snapshot,
)
from pkwbus.master.told import REFUSAL_RETELL
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError

__all__ = ["REFUSAL_RETELL", "SnapshotWriter", "job_result"]

log = logging.getLogger("pkwbus.master.runner")  # what the runner records


class SnapshotWriter:
    """Applies one line's events to the snapshot and the jobs' futures."""

    def __init__(
        self,
        line: str,
        drives: Sequence[DriveSpec],
        snapshot: Snapshot,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.line = line
        self.snapshot = snapshot
        self._out: list[Event] = []  # what this writer makes of the events it applies
        self._refusals = told.Refusals(line, clock)
        self._polls: dict[str, tuple[PollSpec, ...]] = {}
        # What lands in the snapshot's readings: the configured polls.
        self._keys: set[ReadingKey] = set()
        self._silent: set[str] = set()  # drives told to leave their descriptions unanswered
        # Every parameter each drive was asked to describe, the latest asked first (its
        # describer keeps one no longer asked: planning.reload), and those not settled yet.
        self._targets: dict[str, tuple[DescribeTarget, ...]] = {}
        self._waiting: dict[str, set[int]] = {}
        # Drives a reload took away with an exchange out: its end is the line's time alone
        # (a drive of the same name may be on the line already).
        self._leaving: set[str] = set()
        self._totals = snapshot.totals.setdefault(line, LineTotals())
        self._values = DecodedValues()  # a value that holds is decoded once
        self._alarms = LineAlarms(line)  # the polled parameters that tell active alarms
        self._on: dict[type, Callable[[Any, float], None]] = {
            Exchanged: self._exchanged,
            Finished: self._finished,
            HealthChanged: self._health,
            PkwLengthTold: self._pkw_length,
            DescribedAnew: self._settled,
            DescribedFromBook: self._settled,
            LeftUnanswered: self._settled,
            Forgotten: self._forgotten,
            Redecoded: self._redecoded,
        }
        for kind, handler in states.HANDLERS.items():  # the states the events tell
            self._on[kind] = partial(handler, snapshot, line)
        snapshot.lines[line] = False
        for d in drives:
            self.add_drive(d)

    # ------------------------------------------------------------ a reload

    def add_drive(self, spec: DriveSpec) -> None:
        """A drive of the line (at the start, or added by a reload): shown up until it
        fails (a DP slave: down until in data exchange), its values to come, decoded as its
        polls say until it describes them (none of a parameter it is to describe before)."""
        name, snapshot = spec.name, self.snapshot
        self._polls[name] = spec.polls
        self._keys.update((name, p.parameter, p.index) for p in spec.polls)
        self._targets[name] = spec.describe
        waiting = {t.pnu for t in spec.describe} if spec.form is not None else set()
        self._waiting[name] = waiting
        formats = {(p.parameter, p.index): p.fmt for p in spec.polls}
        snapshot.decoding[name] = Decoding(formats, pending=set(waiting))
        snapshot.counts[name] = DriveCounts()
        snapshot.drives[name] = DriveState(up=not spec.carrier.tells_health)
        self._alarms.watch(name, spec.alarms)
        snapshot.changes.touch(name)

    def remove_drive(self, drive: str, *, exchange_out: bool = False) -> None:
        """A drive gone from the line: everything the snapshot shows of it goes; whatever of
        it still ends (``exchange_out``: an exchange of it was out when it went) resolves its
        caller and counts as the line's time, nothing more."""
        self._polls.pop(drive, None)
        self._keys = {k for k in self._keys if k[0] != drive}
        self._targets.pop(drive, None)
        self._waiting.pop(drive, None)
        if exchange_out:
            self._leaving.add(drive)
        self._silent.discard(drive)
        self._refusals.forget(drive)
        self._values.forget(drive)
        self._alarms.forget(drive)
        self.snapshot.forget(drive)

    def forget_line(self) -> None:
        """The line gone from the configuration (its runner stopped): all of it leaves."""
        for drive in list(self._polls):
            self.remove_drive(drive)
        self._leaving.clear()
        self.snapshot.lines.pop(self.line, None)
        self.snapshot.totals.pop(self.line, None)

    def update_polls(
        self, spec: DriveSpec, polls: Sequence[PollSpec], restated: Collection[tuple[int, int]] = ()
    ) -> None:
        """The drive's polls now (as described) and what it is asked to describe (``spec``).
        The values of the polls gone leave, and those decoded otherwise now (a kept poll's, its
        latest, and the latest ``restated``: PNU, subindex) until the next answer. A parameter
        new to its descriptions waits for its description; one described before does not."""
        drive = spec.name
        self._polls[drive] = tuple(polls)
        decoding = self.snapshot.decoding[drive]
        was, now = decoding.formats, {(p.parameter, p.index): p.fmt for p in polls}
        self._keys = {k for k in self._keys if k[0] != drive} | {(drive, *k) for k in now}
        readings, latest = self.snapshot.readings, self.snapshot.latest
        for key in [k for k in readings if k[0] == drive and k[1:] not in now]:
            del readings[key]
        for poll in polls:
            at = (poll.parameter, poll.index)
            if at in was and was[at] != now[at]:
                readings.pop((drive, *at), None)
                latest.pop((drive, poll.request.pnu, poll.request.subindex), None)
        for pnu, subindex in restated:
            latest.pop((drive, pnu, subindex), None)
        old = self._targets.get(drive, ())
        known = {t.pnu for t in old}
        asked = {t.pnu for t in spec.describe}
        self._targets[drive] = (*spec.describe, *(t for t in old if t.pnu not in asked))
        waiting = self._waiting.setdefault(drive, set())
        if spec.form is not None:
            waiting |= asked - known
            decoding.pending = waiting & asked
        decoding.formats = now
        if self._alarms.watch(drive, spec.alarms):
            self._show_alarms(drive)  # what a parameter no longer watched showed
        self.snapshot.changes.touch(drive)

    def apply(self, events: Sequence[Event], at: float | None = None) -> list[Event]:
        """Apply ``events``; ``at`` is when they happened (``time.time()``; default: now).
        What the writer made of them: its own events, for the line's observers."""
        if at is None:
            at = time.time()
        out: list[Event] = []
        self._out = out
        on = self._on
        for event in events:
            handler = on.get(type(event))
            if handler is not None:
                handler(event, at)
        return out

    def _exchanged(self, event: Exchanged, at: float) -> None:
        # One exchange is out at a time: the first to end of a drive that left is its own.
        if gone := event.drive in self._leaving:
            self._leaving.discard(event.drive)
        if event.error is ErrorKind.PORT:
            return  # nothing went on the wire
        totals = self._totals
        totals.telegrams += 1
        totals.busy += event.busy
        if gone:
            return  # not the errors of a drive of its name added since
        if event.error is not None and (counts := self.snapshot.counts.get(event.drive)):
            counts.errors += 1
            self.snapshot.changes.touch(event.drive)

    def _decode_as(self, decoding: Decoding, event: DescriptionSettled | Redecoded) -> None:
        """The event's polls decode as now described, from now on."""
        for poll in event.polls:
            decoding.formats[(poll.parameter, poll.index)] = poll.fmt
            layers = poll.layers
            source = resolve(layers, event.description).source if layers else "none"
            decoding.sources[poll.parameter] = source

    def _decoding(self, drive: str) -> Decoding | None:
        decoding = self.snapshot.decoding.get(drive)
        if decoding is not None:
            self.snapshot.changes.touch(drive)
        return decoding  # None: a drive gone from the line

    def _redecoded(self, event: Redecoded, at: float) -> None:
        """New polls of a parameter told before (a reload): nothing to log again."""
        if (decoding := self._decoding(event.drive)) is not None:
            self._decode_as(decoding, event)
            self._described(event.drive, decoding, event.target.pnu)  # its describer has it
            self._out.append(DescriptionChecked(event))

    def _described(self, drive: str, decoding: Decoding, pnu: int) -> None:
        """``pnu``'s description settled: its values and the API's reads and writes go."""
        decoding.pending.discard(pnu)
        self._waiting.get(drive, set()).discard(pnu)

    def _forgotten(self, event: Forgotten, at: float) -> None:
        """Another drive now: no value of its parameters until it described them."""
        drive, target = event.drive, event.target
        if (decoding := self._decoding(drive)) is None:
            return
        if target == next(iter(self._targets.get(drive, ())), None):  # one line a drive
            log.warning("drive %s is %s: its parameters are described afresh", drive,
                        event.why, extra={"line": self.line, "drive": drive})  # fmt: skip
        decoding.pending.add(target.pnu)
        self._waiting.setdefault(drive, set()).add(target.pnu)
        decoding.described.pop(target.pnu, None)
        self._out.append(DescriptionChecked(event))

    def _settled(self, event: DescriptionSettled, at: float) -> None:
        """A parameter's description settled: its polls decode as it says from now on; one
        log line when the drive gave none, one per field it contradicts the catalog on."""
        drive, target, found = event.drive, event.target, event.description
        if (decoding := self._decoding(drive)) is None:
            return
        self._described(drive, decoding, target.pnu)
        if found is not None:
            decoding.described[target.pnu] = found
        else:
            decoding.described.pop(target.pnu, None)
        self._decode_as(decoding, event)
        new = {(p.parameter, p.index): p for p in event.polls}
        self._polls[drive] = tuple(
            new.get((p.parameter, p.index), p) for p in self._polls.get(drive, ())
        )
        if isinstance(event, LeftUnanswered) and drive not in self._silent:
            self._silent.add(drive)  # one line for all its parameters still waiting
            told.unanswered(self.line, event)
        elif found is not None:
            self._silent.discard(drive)
        contradicts = told.described(self.line, event)
        self._out.append(DescriptionChecked(event, tuple(contradicts)))

    def _pkw_length(self, event: PkwLengthTold, at: float) -> None:
        told.pkw_length(self.line, event)

    def _health(self, event: HealthChanged, at: float) -> None:
        told.health(self.line, event)
        old = self.snapshot.drives.get(event.drive, DriveState())
        self.snapshot.drives[event.drive] = replace(old, up=event.up)
        self.snapshot.changes.touch(event.drive)

    def _finished(self, event: Finished, at: float) -> None:
        work, drive = event.work, event.drive
        if event.gone or drive not in self._polls:  # gone from the line: its caller alone
            if isinstance(work, ProbeJob):
                work.resolve(JobResult(event.outcome, tally=event.tally))
            elif isinstance(work, Job):
                work.resolve(self._result(event, work))
            return
        self._count(drive, event)
        if isinstance(work, ProbeJob):  # it answered or not: no value, nothing to remember
            result = JobResult(event.outcome, tally=event.tally)
            self._out.append(JobDone(drive, work.kind, result))
            work.resolve(result)
            return
        response = event.outcome.response if isinstance(event.outcome, Answered) else None
        if isinstance(response, pkw.ValueResponse) and response.vtype is not None:
            self.snapshot.stated[(drive, work.request.pnu)] = response.vtype  # its own type
        result = self._result(event, work)
        if isinstance(work, PollSpec):
            self._refusals.tell(drive, work, event.outcome)
            self._out.append(JobDone(drive, JobKind.READ, result))
            key = (drive, work.parameter, work.index)
            # Still polled, and decoded as its values are shown now (a poll out when a
            # reload changed it is not): its value is the parameter's latest, and shown.
            if key in self._keys and self._decoded_as_now(drive, work):
                reading, _ = self._remember(drive, work.request, result, at)
                if reading is not None:
                    self._land(key, reading)
            return
        reading, previous = self._remember(drive, work.request, result, at)
        if reading is not None:
            self._show_confirmed(drive, work, reading)
        if event.tally is not None and not isinstance(event.outcome, Cancelled):
            result = replace(result, previous=previous)  # it ran: a write's old value
        self._out.append(JobDone(drive, work.kind, result))
        work.resolve(result)

    def _decoded_as_now(self, drive: str, poll: PollSpec) -> bool:
        """Whether ``poll``'s value is decoded as its values are shown now (a poll out when a
        reload changed its format is not)."""
        fmt = self.snapshot.decoding[drive].formats.get((poll.parameter, poll.index))
        return fmt is poll.fmt or fmt == poll.fmt

    def _count(self, drive: str, event: Finished) -> None:
        """A fault answer, or answers the request did not ask for, counted for the page."""
        unexpected = event.tally.errors.get(ErrorKind.UNEXPECTED, 0) if event.tally else 0
        faulted = isinstance(event.outcome, Rejected)
        if unexpected or faulted:
            counts = self.snapshot.counts[drive]
            counts.errors += unexpected
            counts.faults += faulted
            self.snapshot.changes.touch(drive)

    def _result(self, event: Finished, work: Job | PollSpec) -> JobResult:
        try:
            return self._values.result(
                event.drive, event.outcome, event.tally, work.request, work.fmt
            )
        except RemoteProtocolError as exc:
            ctx = {"line": self.line, "drive": event.drive}
            log.warning("%s/%s: %s", self.line, event.drive, exc, extra=ctx)
            return JobResult(TimedOut(f"unusable answer: {exc}"), tally=event.tally)

    def _remember(
        self, drive: str, request: pkw.PkwRequest, result: JobResult, at: float
    ) -> tuple[Reading | None, Reading | None]:
        """(the value the drive just confirmed, the latest one before it).

        An answer that carries the parameter's value - a poll, a read, or a write
        the drive acknowledged by echoing the value it now holds - makes that value
        the parameter's latest, so that the next write's old value is not stale.
        """
        key = (drive, request.pnu, request.subindex)
        previous = self.snapshot.latest.get(key)
        if result.value is None:
            return None, previous
        reading = Reading(result.value, result.raw, at)
        self.snapshot.latest[key] = reading
        self.snapshot.changes.touch(drive)
        return reading, previous

    def _show_confirmed(self, drive: str, job: Job, reading: Reading) -> None:
        """A polled parameter shows what a read or an acknowledged write confirmed,
        when the job decoded it as the poll does."""
        if job.request.pnu in self.snapshot.decoding[drive].pending:
            return  # decoded as the catalog says, before the drive described it
        for spec in self._polls.get(drive, ()):
            same = spec.request.pnu == job.request.pnu
            if same and spec.request.subindex == job.request.subindex and spec.fmt == job.fmt:
                self._land((drive, spec.parameter, spec.index), reading)

    def _land(self, key: ReadingKey, reading: Reading) -> None:
        snapshot = self.snapshot
        snapshot.readings[key] = reading
        snapshot.counts[key[0]].landed = reading.timestamp
        self._out.append(ValueLanded(key, reading))
        decoder = self._alarms.decoders.get(key)
        if decoder is not None and self._alarms.landed(key, decoder, reading):
            self._show_alarms(key[0])

    def _show_alarms(self, drive: str) -> None:
        """The drive's active alarms and warnings, as its alarm parameters show them now."""
        active = self._alarms.active(drive)
        if active:
            self.snapshot.alarms[drive] = active
        else:
            self.snapshot.alarms.pop(drive, None)
        self.snapshot.changes.touch(drive)
