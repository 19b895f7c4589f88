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
from collections.abc import Callable, Sequence
from dataclasses import replace

from pkwbus.catalog.description import ParameterDescription
from pkwbus.catalog.precedence import Disagreement, disagreements
from pkwbus.master.events import (
    DescriptionChecked,
    Event,
    JobDone,
    LineState,
    MaintenanceChanged,
    SlaveDiagnosed,
    SlaveStateChanged,
    ValueLanded,
)
from pkwbus.master.planning.describing import ASK_AGAIN
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, JobResult, ProbeJob
from pkwbus.master.planning.outcomes import Answered, Outcome, Rejected, TimedOut
from pkwbus.master.planning.plan import (
    Described,
    DriveSpec,
    Finished,
    HealthChanged,
    PkwLengthTold,
    PollSpec,
    StatusWord,
)
from pkwbus.master.planning.transaction import Tally
from pkwbus.master.snapshot import (
    DriveState,
    LiveSlave,
    Maintained,
    Reading,
    ReadingKey,
    Snapshot,
)
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw.length import AUTO, shown

__all__ = ["REFUSAL_RETELL", "SnapshotWriter", "job_result"]

log = logging.getLogger("pkwbus.master.runner")  # what the runner records

REFUSAL_RETELL = 24 * 3600.0  # seconds between log lines of a poll the drive keeps refusing


def job_result(
    outcome: Outcome, tally: Tally | None, request: pkw.PkwRequest, fmt: ParameterDescription
) -> JobResult:
    """The result of a finished job: its value when the answer carries one.

    RemoteProtocolError when the answer carries a value that cannot be decoded.
    """
    if not isinstance(outcome, Answered):
        return JobResult(outcome, tally=tally)
    if not isinstance(outcome.response, pkw.ValueResponse | pkw.TextResponse):
        return JobResult(outcome, tally=tally)  # a description element, a count: no value
    raw, value = fmt.value_of(outcome.response)
    return JobResult(outcome, raw, value, tally)


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
        self._clock = clock
        # A poll the drive refuses, by (drive, parameter, index): when it was last told.
        self._refused: dict[tuple[str, str, int], float] = {}
        self._polls = {d.name: d.polls for d in drives}
        # What lands in the snapshot's readings: the configured polls.
        self._keys = {(d.name, p.parameter, p.index) for d in drives for p in d.polls}
        # Parameters whose description is awaited: no value of theirs lands before it.
        self._waiting = {(d.name, t.pnu) for d in drives if d.form is not None for t in d.describe}
        self._silent: set[str] = set()  # drives told to leave their descriptions unanswered
        self._targets = {d.name: d.describe for d in drives}
        snapshot.lines[line] = False
        for d in drives:
            snapshot.drives[d.name] = DriveState()

    # ------------------------------------------------------------ a reload

    def add_drive(self, spec: DriveSpec) -> None:
        """A drive added to the line: shown up until it fails, its values to come."""
        self._polls[spec.name] = spec.polls
        self._keys.update((spec.name, p.parameter, p.index) for p in spec.polls)
        self._targets[spec.name] = spec.describe
        if spec.form is not None:
            self._waiting.update((spec.name, t.pnu) for t in spec.describe)
        self.snapshot.drives[spec.name] = DriveState()

    def remove_drive(self, drive: str) -> None:
        """A drive gone from the line: everything the snapshot shows of it goes; whatever of
        it still ends (an exchange out when it went) resolves its caller, nothing more."""
        self._polls.pop(drive, None)
        self._keys = {k for k in self._keys if k[0] != drive}
        self._targets.pop(drive, None)
        self._silent.discard(drive)
        self._waiting = {w for w in self._waiting if w[0] != drive}
        self._refused = {k: v for k, v in self._refused.items() if k[0] != drive}
        self.snapshot.forget(drive)

    def update_polls(self, drive: str, polls: Sequence[PollSpec]) -> None:
        """The drive's polls now (as described); the values of those gone leave."""
        self._polls[drive] = tuple(polls)
        now = {(p.parameter, p.index) for p in polls}
        self._keys = {k for k in self._keys if k[0] != drive} | {(drive, *k) for k in now}
        readings = self.snapshot.readings
        for key in [k for k in readings if k[0] == drive and k[1:] not in now]:
            del readings[key]

    def apply(self, events: Sequence[Event], at: float | None = None) -> list[Event]:
        """Apply ``events``; ``at`` is when they happened (``time.time()``; default: now).
        What the writer made of them: its own events, for the line's observers."""
        if at is None:
            at = time.time()
        out: list[Event] = []
        self._out = out
        snapshot = self.snapshot
        for event in events:
            if isinstance(event, Finished):
                self._finished(event, at)
            elif isinstance(event, StatusWord):
                old = snapshot.drives.get(event.drive, DriveState())
                snapshot.drives[event.drive] = DriveState(old.up, event.word, at, event.main_actual)
            elif isinstance(event, HealthChanged):
                self._health(event)
            elif isinstance(event, PkwLengthTold):
                self._pkw_length(event)
            elif isinstance(event, Described):
                self._described(event)
            elif isinstance(event, LineState):
                snapshot.lines[event.line] = event.up
            elif isinstance(event, MaintenanceChanged):
                self._maintenance(event, at)
            elif isinstance(event, SlaveStateChanged):
                old_slave = snapshot.slaves.get(event.drive, LiveSlave(self.line))
                snapshot.slaves[event.drive] = replace(old_slave, state=event.state)
            elif isinstance(event, SlaveDiagnosed):
                old_slave = snapshot.slaves.get(event.drive, LiveSlave(self.line))
                found = event.diagnosis
                snapshot.slaves[event.drive] = replace(
                    old_slave, ident=found.ident, owner=found.master, flags=found.flags,
                    diagnosed=at,
                )  # fmt: skip
        return out

    def _described(self, event: Described) -> None:
        """A parameter's description settled: its polls decode as it says from now on; one
        log line when the drive gave none, one per field it contradicts the catalog on."""
        drive, target, found = event.drive, event.target, event.description
        ctx = {"line": self.line, "drive": drive}
        if event.reloaded:  # new polls of a parameter told before: nothing to log again
            self._out.append(DescriptionChecked(event))
            return
        if event.forgotten:  # another drive now: no value of its parameters until described
            if target == next(iter(self._targets.get(drive, ())), None):  # one line a drive
                log.warning("drive %s is %s: its parameters are described afresh", drive,
                            event.why, extra=ctx)  # fmt: skip
            self._waiting.add((drive, target.pnu))
            self._out.append(DescriptionChecked(event))
            return
        self._waiting.discard((drive, target.pnu))
        new = {(p.parameter, p.index): p for p in event.polls}
        self._polls[drive] = tuple(
            new.get((p.parameter, p.index), p) for p in self._polls.get(drive, ())
        )
        contradicts: list[Disagreement] = []
        if found is None:
            if event.unanswered and drive not in self._silent:
                self._silent.add(drive)  # one line for all its parameters still waiting
                log.warning("drive %s: %s: the catalog's descriptions are used for the"
                            " parameters still waiting, and it is asked again in %d minutes",
                            drive, event.why, ASK_AGAIN // 60, extra=ctx)  # fmt: skip
            elif event.unanswered:
                pass
            elif event.first and not event.withheld:
                log.info("drive %s: %s: %s; the catalog's description is used", drive,
                         target.parameter, event.why, extra=ctx)  # fmt: skip
        else:
            self._silent.discard(drive)
        if event.withheld and event.first:
            log.info(
                "drive %s: %s is not polled: no vendor document types it, and the drive did"
                " not describe its type (%s)", drive, target.parameter,
                event.why or "no type in its description", extra=ctx,
            )  # fmt: skip
        if found is not None and found.read_only and target.writable and event.first:
            log.warning(
                "drive %s describes %s as read-only, but the configuration lists it as"
                " writable: the drive will refuse its writes", drive, target.parameter,
                extra=ctx,
            )  # fmt: skip
        if found is not None and target.catalog is not None:
            contradicts = disagreements(found, target.catalog)
            for d in contradicts:
                log.warning(
                    "drive %s: %s: the drive gives its %s as %s, the catalog as %s; the"
                    " drive's is used", drive, target.parameter, d.field, d.drive, d.catalog,
                    extra=ctx,
                )  # fmt: skip
        self._out.append(DescriptionChecked(event, tuple(contradicts)))

    def _maintenance(self, event: MaintenanceChanged, at: float) -> None:
        """A drive in maintenance, or out of it: one log line each."""
        drive, ctx = event.drive, {"line": self.line, "drive": event.drive}
        if event.on:
            self.snapshot.maintenance[drive] = Maintained(event.reason, at)
            log.warning("drive %s is in maintenance (%s): nothing goes out to it", drive,
                        event.reason or "no reason given", extra=ctx)  # fmt: skip
        elif self.snapshot.maintenance.pop(drive, None) is not None:
            log.warning("drive %s is out of maintenance: it is polled again", drive, extra=ctx)

    def _pkw_length(self, event: PkwLengthTold) -> None:
        """One log line per change of what a drive's PKW length is known to be."""
        length, drive = event.length, event.drive
        ctx = {"line": self.line, "drive": drive}
        conflict = length.conflict
        if not isinstance(conflict, str):
            log.warning(
                "drive %s answers with a PKW length of %s, but pkw_words is %s: no write goes"
                " out to it until they agree (set pkw_words: %s, or auto)",
                drive, shown(conflict), shown(length.configured),
                "127" if conflict is None else conflict, extra=ctx,
            )  # fmt: skip
        elif length.configured != AUTO:
            log.info("drive %s answers with its configured PKW length again", drive, extra=ctx)
        elif length.known:
            log.info("drive %s: PKW length %s, learned from its answers", drive,
                     shown(length.words), extra=ctx)  # fmt: skip

    def _health(self, event: HealthChanged) -> None:
        ctx = {"line": self.line, "drive": event.drive}
        if event.reason and event.up:
            log.info("drive %s %s", event.drive, event.reason, extra=ctx)
        elif event.reason:
            log.warning(
                "drive %s is down: %s (probing at back-off)", event.drive, event.reason, extra=ctx
            )
        old = self.snapshot.drives.get(event.drive, DriveState())
        self.snapshot.drives[event.drive] = replace(old, up=event.up)

    def _finished(self, event: Finished, at: float) -> None:
        work, drive = event.work, event.drive
        if event.gone or drive not in self._polls:  # gone from the line: its caller alone
            if isinstance(work, ProbeJob):
                work.resolve(JobResult(event.outcome, tally=event.tally))
            elif isinstance(work, Job):
                work.resolve(self._result(event, work))
            return
        if isinstance(work, ProbeJob):  # it answered or not: no value, nothing to remember
            result = JobResult(event.outcome, tally=event.tally)
            self._out.append(JobDone(drive, work.kind, result))
            work.resolve(result)
            return
        response = event.outcome.response if isinstance(event.outcome, Answered) else None
        if isinstance(response, pkw.ValueResponse) and response.vtype is not None:
            self.snapshot.stated[(drive, work.request.pnu)] = response.vtype  # its own type
        result = self._result(event, work)
        reading, previous = self._remember(drive, work.request, result, at)
        if isinstance(work, PollSpec):
            self._tell_refusal(drive, work, event.outcome)
            self._out.append(JobDone(drive, JobKind.READ, result))
            key = (drive, work.parameter, work.index)
            if reading is not None and key in self._keys:  # still polled (a reload)
                self._land(key, reading)
            return
        if reading is not None:
            self._show_confirmed(drive, work, reading)
        if event.tally is not None and not isinstance(event.outcome, Cancelled):
            result = replace(result, previous=previous)  # it ran: a write's old value
        self._out.append(JobDone(drive, work.kind, result))
        work.resolve(result)

    def _tell_refusal(self, drive: str, poll: PollSpec, outcome: Outcome) -> None:
        """A poll the drive refuses is logged once with the fault text, then once a day
        while the refusals last; its first answer after them is logged too."""
        key = (drive, poll.parameter, poll.index)
        ctx = {"line": self.line, "drive": drive}
        where = poll.parameter + (f"[{poll.index}]" if poll.index else "")
        if isinstance(outcome, Rejected):
            now = self._clock()
            told = self._refused.get(key)
            if told is None or now - told >= REFUSAL_RETELL:
                again = "" if told is None else " (still, every poll)"
                log.warning(
                    "drive %s refuses the poll of %s%s: %s",
                    drive, where, again, outcome.text or outcome.short, extra=ctx,
                )  # fmt: skip
                self._refused[key] = now
        elif isinstance(outcome, Answered) and self._refused.pop(key, None) is not None:
            log.info("drive %s answers the poll of %s again", drive, where, extra=ctx)

    def _result(self, event: Finished, work: Job | PollSpec) -> JobResult:
        try:
            return job_result(event.outcome, event.tally, work.request, work.fmt)
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
        return reading, previous

    def _show_confirmed(self, drive: str, job: Job, reading: Reading) -> None:
        """A polled parameter shows what a read or an acknowledged write confirmed,
        when the job decoded it as the poll does."""
        if (drive, job.request.pnu) in self._waiting:
            return  # decoded as the catalog says, before the drive described it
        for spec in self._polls.get(drive, ()):
            same = spec.request.pnu == job.request.pnu
            if same and spec.request.subindex == job.request.subindex and spec.fmt == job.fmt:
                self._land((drive, spec.parameter, spec.index), reading)

    def _land(self, key: ReadingKey, reading: Reading) -> None:
        self.snapshot.readings[key] = reading
        self._out.append(ValueLanded(key, reading))
