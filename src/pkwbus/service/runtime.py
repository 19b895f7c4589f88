"""The running service's object graph: lines with their runners, drives, snapshot, metrics.

Built from the configuration by :mod:`pkwbus.service.assembly.build`; started and
stopped by :mod:`pkwbus.service.assembly.serve`. The HTTP API reads the snapshot and
queues jobs through :meth:`Runtime.submit`.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Protocol

from prometheus_client import CollectorRegistry

from pkwbus.catalog.alarms import ActiveAlarm
from pkwbus.catalog.description import (
    OTHER_INDEX,
    ParameterDescription,
    ParameterKey,
    ParameterTable,
)
from pkwbus.catalog.precedence import Layers, resolve
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, JobResult, Priority
from pkwbus.master.planning.plan import PollSpec
from pkwbus.master.snapshot import ReadingKey, Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.values import ParameterRef
from pkwbus.protocol.values.types import ValueType

__all__ = [
    "Alarms",
    "DriveEntry",
    "History",
    "LineCounts",
    "LineTask",
    "Runtime",
    "Settings",
    "Trends",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DriveEntry:
    """A configured drive as the service knows it: its parameters resolved at build time.

    It holds no configuration model: what a parameter is, whether it may be
    written and its name on the drive come from ``parameters``.
    """

    name: str
    line: str
    target: DriveTarget
    polls: tuple[PollSpec, ...] = ()
    parameters: ParameterTable = field(default_factory=ParameterTable)
    # The unit of each polled parameter, by its name on the drive (as now described).
    units: dict[str, str] = field(default_factory=dict)
    # What the configuration sets explicitly and the catalog says, of each parameter the
    # configuration names, keyed as ParameterTable.configured.
    layers: Mapping[ParameterKey, Layers] = field(default_factory=lambda: MappingProxyType({}))
    # What the drive described of its parameters, by PNU, as their descriptions settle.
    described: dict[int, DriveDescription] = field(default_factory=dict)
    # PNUs the drive is describing: no API read or write of theirs until it has.
    pending: set[int] = field(default_factory=set)
    # Where each polled parameter's description came from (catalog.precedence.SOURCES).
    sources: dict[str, str] = field(default_factory=dict)
    # Each polled (parameter, index) as it is decoded now.
    formats: dict[tuple[str, int], ParameterDescription] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for poll in self.polls:
            self.formats.setdefault((poll.parameter, poll.index), poll.fmt)

    @property
    def access(self) -> str:
        """The channel its parameters go through: ``pkw``, or ``ds47`` (data record 47)."""
        return "pkw" if self.target.record is None else "ds47"

    def may_write(self, ref: ParameterRef) -> bool:
        """Whether the drive's ``writable`` list allows writing ``ref``."""
        return self.parameters.describe(ref).writable

    def format_of(self, ref: ParameterRef, stated: ValueType | None = None) -> ParameterDescription:
        """What is known of ``ref``: type, scaling, unit, limits (empty when nothing); the
        configuration first, then what the drive described, then the catalog; where none
        of them types it, the type the drive ``stated`` in its answers."""
        described = self._described(ref)
        if described.vtype is None and stated is not None:
            return described.with_type(stated)
        return described

    def _described(self, ref: ParameterRef) -> ParameterDescription:
        known = self.parameters.describe(ref)
        drive = self.described.get(ref.pnu)
        if drive is None:
            return known
        keys: tuple[ParameterKey, ...] = ((ref.pnu, ref.index),)
        if ref.index is not None:
            keys += ((ref.pnu, OTHER_INDEX), (ref.pnu, None))
        layers = next((self.layers[k] for k in keys if k in self.layers), None)
        if layers is None:  # the configuration says nothing of it
            layers = Layers(known, catalog=self.parameters.catalog.get(ref.pnu))
        return resolve(layers, drive).description

    def canonical(self, ref: ParameterRef) -> ParameterRef:
        """The drive's one name for ``ref`` (3-41 for 341); LocalProtocolError for a
        notation the drive does not use."""
        return self.parameters.canonical(ref)

    def unit_of(self, parameter: str) -> str:
        return self.units.get(parameter, "")


class LineCounts(Protocol):
    """Plain counts of one line: busy seconds, telegrams, and faults and telegram errors
    by drive."""

    @property
    def busy_total(self) -> float: ...

    @property
    def telegram_total(self) -> int: ...

    @property
    def fault_counts(self) -> Mapping[str, int]: ...

    @property
    def error_counts(self) -> Mapping[str, int]: ...


class LineTask(Protocol):
    """One line's task: a :class:`~pkwbus.master.runner.LineRunner` of any bus."""

    name: str

    def submit(self, job: Job) -> None: ...
    def maintenance(self, drive: str, on: bool, reason: str = "") -> None: ...
    def stop(self) -> None: ...
    async def run(self) -> None: ...


class Alarms(Protocol):
    """The drives' active alarms in words (service.metrics.alarms.AlarmBoard)."""

    def active(self, drive: str) -> list[ActiveAlarm]: ...

    def said(self, key: ReadingKey, value: object) -> str: ...


class History(Protocol):
    """The drives' own log entries as kept (service.history.store.HistoryStore)."""

    def latest(
        self, *, drive: str | None = None, since: float | None = None, limit: int = 100
    ) -> list[Any]: ...


class Settings(Protocol):
    """The drives' settings as swept (service.history.settings.SettingsWatcher)."""

    @property
    def swept(self) -> Mapping[str, Any]: ...

    def view(self, drive: str) -> dict[str, Any]: ...

    async def accept(self, drive: str) -> int: ...

    async def written(
        self, drive: str, pnu: int, index: int, raw: int, value: Any, *, answered: bool = True
    ) -> None: ...


class Trends(Protocol):
    """The last minutes of each polled value (service.metrics.trends.Trends)."""

    def points(self, key: ReadingKey, now: float) -> list[float | None]: ...


class Runtime:
    def __init__(
        self,
        runners: Iterable[LineTask],
        drives: Iterable[DriveEntry],
        snapshot: Snapshot,
        registry: CollectorRegistry,
        *,
        job_timeout: float = 5.0,
        alarms: Alarms | None = None,
        trends: Trends | None = None,
    ) -> None:
        self.runners = {s.name: s for s in runners}
        self.drives = {d.name: d for d in drives}
        self.snapshot = snapshot
        self.registry = registry
        self.job_timeout = job_timeout
        self.alarms = alarms  # the drives' active alarms, in words (None: none are watched)
        self.trends = trends  # the values' last minutes, for the page (None: none kept)
        self.history: History | None = None  # the drives' own log entries (None: not kept)
        self.settings: Settings | None = None  # the sweep of the drives' settings (None: none)
        self._tasks: dict[str, asyncio.Task[None]] = {}
        # What starts once the lines run (the watch of the drives' logs), and what ends
        # after they stopped.
        self.starters: list[Callable[[], Awaitable[None]]] = []
        self.cleanups: list[Callable[[], object]] = []
        # What closes a line's simulated drives, after the line stopped.
        self.closers: dict[str, Callable[[], object]] = {}
        # What the status page shows of each line besides the snapshot (service.metrics).
        self.counts: dict[str, LineCounts] = {}

    async def start(self) -> None:
        for runner in self.runners.values():
            self.start_line(runner)
        for start in self.starters:
            await start()

    def start_line(self, runner: LineTask) -> None:
        """Run ``runner``'s line (at the start, or a line a reload added)."""
        self.runners[runner.name] = runner
        task = asyncio.create_task(runner.run(), name=f"line {runner.name}")
        task.add_done_callback(self._line_ended)
        self._tasks[runner.name] = task

    async def stop_line(self, name: str, grace: float = 3.0) -> None:
        """Stop one line (a reload): its exchange in flight finishes, its port closes."""
        runner = self.runners.pop(name)
        runner.stop()
        task = self._tasks.pop(name, None)
        if task is not None:
            await self._end([task], grace)
        await self._close(name)

    async def _end(self, tasks: list[asyncio.Task[None]], grace: float) -> None:
        _, pending = await asyncio.wait(tasks, timeout=grace)
        for task in pending:
            task.cancel()
        if pending:
            await asyncio.wait(pending, timeout=1.0)

    async def _close(self, name: str) -> None:
        close = self.closers.pop(name, None)
        result = close() if close is not None else None
        if asyncio.iscoroutine(result):
            await result

    def _line_ended(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            log.error("%s stopped: %r", task.get_name(), task.exception())

    async def stop(self, grace: float = 3.0) -> None:
        """Stop taking jobs, let each line finish its exchange in flight, close the ports."""
        for runner in self.runners.values():
            runner.stop()
        if self._tasks:
            await self._end(list(self._tasks.values()), grace)
        for name in list(self.closers):
            await self._close(name)
        for cleanup in reversed(self.cleanups):
            result = cleanup()
            if asyncio.iscoroutine(result):
                await result

    def submit(
        self,
        drive: str,
        request: pkw.PkwRequest,
        kind: JobKind,
        fmt: ParameterDescription,
        *,
        timeout: float | None = None,
        parameter: str = "",
        index: int = 0,
    ) -> asyncio.Future[JobResult]:
        """Queue a job on the drive's line; the future gets its result."""
        entry = self.drives[drive]
        loop = asyncio.get_running_loop()
        future: asyncio.Future[JobResult] = loop.create_future()
        job = Job(
            drive,
            request,
            kind,
            Priority.WRITE if kind is JobKind.WRITE else Priority.READ,
            loop.time() + (timeout or self.job_timeout),
            fmt,
            future,
            parameter,
            index,
        )
        runner = self.runners.get(entry.line)
        if runner is None:
            future.set_result(JobResult(Cancelled("no such line")))
        else:
            runner.submit(job)
        return future
