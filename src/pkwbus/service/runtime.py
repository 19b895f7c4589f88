"""The running service's object graph: the configuration's load (lines with their runners,
drives), the snapshot, metrics. Built by :mod:`pkwbus.service.assembly`, started and
stopped by :mod:`pkwbus.service.assembly.serve`; the HTTP API reads the snapshot and
queues jobs through :meth:`Runtime.submit`."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from prometheus_client import CollectorRegistry

from pkwbus.catalog.alarms import AlarmDecoder
from pkwbus.catalog.description import (
    OTHER_INDEX,
    ParameterDescription,
    ParameterKey,
    ParameterTable,
)
from pkwbus.catalog.precedence import Layers, resolve
from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import Observer, Outputs
from pkwbus.master.planning.carrier import Item, Preview
from pkwbus.master.planning.jobs import Cancelled, Job, JobKind, JobResult, Priority
from pkwbus.master.planning.plan import PollSpec
from pkwbus.master.snapshot import Maintained, Snapshot
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.values import ParameterRef
from pkwbus.protocol.values.types import ValueType
from pkwbus.service.roles import History, LineMaster, LineTask, Masters, Settings, Trends

__all__ = [
    "DriveEntry",
    "History",
    "LineMaster",
    "LineTask",
    "Load",
    "Masters",
    "Runtime",
    "Settings",
    "Trends",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DriveEntry:
    """A configured drive as the service knows it: its parameters resolved at build time,
    never changed after (a reload makes a new entry). What the drive described since, and
    how its values are decoded now, is the snapshot's (:class:`~pkwbus.master.snapshot.Decoding`).

    It holds no configuration model: what a parameter is, whether it may be
    written and its name on the drive come from ``parameters``.
    """

    name: str
    line: str
    target: DriveTarget
    polls: tuple[PollSpec, ...] = ()
    parameters: ParameterTable = field(default_factory=ParameterTable)
    # What the configuration sets explicitly and the catalog says, of each parameter the
    # configuration names, keyed as ParameterTable.configured.
    layers: Mapping[ParameterKey, Layers] = field(default_factory=lambda: MappingProxyType({}))
    # Where each polled parameter's description comes from before the drive described it
    # (catalog.precedence.SOURCES): the configuration, the catalog or none.
    sources: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    # The polled parameters the catalog's alarm table tells in words (by parameter and
    # index): what the page shows of their values (pkwbus.master.alarms.said).
    alarm_words: Mapping[tuple[str, int], AlarmDecoder] = field(
        default_factory=lambda: MappingProxyType({})
    )

    @property
    def access(self) -> str:
        """The channel its parameters go through: ``pkw``, or ``ds47`` (data record 47)."""
        return "pkw" if self.target.record is None else "ds47"

    def may_write(self, ref: ParameterRef) -> bool:
        """Whether the drive's ``writable`` list allows writing ``ref``."""
        return self.parameters.describe(ref).writable

    def format_of(
        self,
        ref: ParameterRef,
        described: Mapping[int, DriveDescription],
        stated: ValueType | None = None,
    ) -> ParameterDescription:
        """What is known of ``ref``: type, scaling, unit, limits (empty when nothing); the
        configuration first, then what the drive ``described`` (by PNU), then the catalog;
        where none of them types it, the type the drive ``stated`` in its answers."""
        found = self._described(ref, described.get(ref.pnu))
        if found.vtype is None and stated is not None:
            return found.with_type(stated)
        return found

    def _described(self, ref: ParameterRef, drive: DriveDescription | None) -> ParameterDescription:
        known = self.parameters.describe(ref)
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


@dataclass(frozen=True)
class Load:
    """What one load of the configuration made: the lines' runners, the drives, who masters
    the lines, the drives' memory, what starts and stops with it. Built once by the
    assembly (service.assembly.loading.LoadBuilder), never changed: a reload, or a line won
    or lost in hot standby, makes the next, swapped in whole (:meth:`Runtime.swap`)."""

    runners: Mapping[str, LineTask] = field(default_factory=dict)
    drives: Mapping[str, DriveEntry] = field(default_factory=dict)
    job_timeout: float = 5.0
    history: History | None = None  # the drives' own log entries (None: not kept)
    settings: Settings | None = None  # the sweep of the drives' settings (None: none)
    masters: Masters | None = None  # hot standby: who masters each line (None: all here)
    # The lines' outputs: the part there from the start and over reloads (the collector,
    # the trends, the description keeper, MQTT), and the drives' log and settings watchers
    # of this load; Runtime.swap gives the lines both, as one list.
    base: tuple[Observer, ...] = ()
    watchers: tuple[Observer, ...] = ()
    # What starts once the lines run, what ends after they stopped, and what closes a
    # line's simulated drives after the line stopped.
    starters: tuple[Callable[[], Awaitable[None]], ...] = ()
    cleanups: tuple[Callable[[], object], ...] = ()
    closers: Mapping[str, Callable[[], object]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("runners", "drives", "closers"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))
        for name in ("base", "watchers", "starters", "cleanups"):
            object.__setattr__(self, name, tuple(getattr(self, name)))


class Runtime:
    """The running service: the current :class:`Load`, and what the process keeps across
    loads (the snapshot, registry, outputs, trends, the lines' tasks, stopping)."""

    def __init__(
        self,
        snapshot: Snapshot,
        registry: CollectorRegistry,
        load: Load | None = None,
        *,
        trends: Trends | None = None,
        outputs: Outputs | None = None,
    ) -> None:
        self.snapshot = snapshot
        self.registry = registry
        self.trends = trends  # the values' last minutes, for the page (None: none kept)
        # What every line's stream goes to (given to each runner at its construction).
        self.outputs = outputs if outputs is not None else Outputs()
        self._load = load if load is not None else Load()
        # The drives the API put in maintenance (why, since when): a reload keeps each on
        # whichever line its drive is; the API's {"on": false} or a restart ends it.
        self._api_maintenance: dict[str, Maintained] = {}
        self.stopping = False  # set by stop(): no line starts from then on
        self._tasks: dict[str, tuple[LineTask, asyncio.Task[None]]] = {}  # by line
        self._ended: set[str] = set()  # lines stopped for good, still in the load
        self._closed: list[Callable[[], object]] = []  # closers, cleanups called

    @property
    def load(self) -> Load:
        return self._load

    def swap(self, load: Load) -> None:
        """``load`` the current one, by one assignment: a reader sees the old or the new;
        the lines' outputs are its outputs from then on (one swap of the one list)."""
        self._load = load
        self.outputs.swap((*load.base, *load.watchers))

    def unwatch(self) -> None:
        """The drives' watchers leave the lines' outputs (they stop: the service stops, or a
        reload watches afresh); the load's base stays."""
        self.outputs.swap(self._load.base)

    @property
    def api_maintenance(self) -> Mapping[str, Maintained]:
        """The drives the API keeps in maintenance (here, or carried from the other master
        in hot standby), with why and since when."""
        return MappingProxyType(self._api_maintenance)

    def hold_maintenance(self, drive: str, held: Maintained) -> Maintained:
        """Keep ``drive`` in maintenance as the API's; one kept already stays as it is. The
        maintenance kept."""
        return self._api_maintenance.setdefault(drive, held)

    def end_maintenance(self, drive: str) -> None:
        """``drive`` no longer kept in maintenance as the API's."""
        self._api_maintenance.pop(drive, None)

    def show_maintenance(self, runner: LineTask, drive: str, *, configured: bool = False) -> None:
        """``drive``'s maintenance on ``runner`` as it is kept: the API's, with its reason and
        since; none unless ``configured`` (the file's, which the line holds itself). Nothing
        on a line that stops (a reload opens it again and holds it then), nor for a drive
        not on it."""
        if runner.stopping:
            return
        held = self._api_maintenance.get(drive)
        with contextlib.suppress(KeyError):
            if held is not None:
                runner.maintenance(drive, True, held.reason, since=held.since)
            elif not configured:
                runner.maintenance(drive, False)

    @property
    def runners(self) -> Mapping[str, LineTask]:
        return self._load.runners

    @property
    def drives(self) -> Mapping[str, DriveEntry]:
        return self._load.drives

    @property
    def history(self) -> History | None:
        return self._load.history

    @property
    def settings(self) -> Settings | None:
        return self._load.settings

    @property
    def masters(self) -> Masters | None:
        return self._load.masters

    def format_of(self, drive: str, ref: ParameterRef) -> ParameterDescription:
        """What is known of the drive's ``ref`` now (:meth:`DriveEntry.format_of`), with
        what the drive described and stated of it."""
        snap = self.snapshot
        decoding = snap.decoding.get(drive)
        described = decoding.described if decoding is not None else {}
        return self.drives[drive].format_of(ref, described, snap.stated.get((drive, ref.pnu)))

    async def start(self) -> None:
        load = self._load
        for runner in load.runners.values():
            self.start_line(runner)
        for start in load.starters:
            await start()

    def start_line(self, runner: LineTask) -> None:
        """Run ``runner``'s line (at the start, or a line a reload added: the load that
        holds it is swapped in by the reload)."""
        task = asyncio.create_task(runner.run(), name=f"line {runner.name}")
        task.add_done_callback(self._line_ended)
        self._tasks[runner.name] = (runner, task)
        self._ended.discard(runner.name)

    async def stop_line(
        self, name: str, grace: float = 3.0, close: Callable[[], object] | None = None
    ) -> None:
        """Stop one line for good (a reload): its exchange in flight finishes, its port
        closes, ``close`` closes its simulated drives, and nothing of it stays in the
        snapshot. No job goes to it from now on; the next load leaves it out."""
        runner, task = self._tasks.pop(name, (self._load.runners.get(name), None))
        self._ended.add(name)
        if runner is not None:
            runner.stop()
            if task is not None:
                await self._end([task], grace)
            runner.forget()
        await self._close(close)

    async def _end(self, tasks: list[asyncio.Task[None]], grace: float) -> None:
        _, pending = await asyncio.wait(tasks, timeout=grace)
        for task in pending:
            task.cancel()
        if pending:
            await asyncio.wait(pending, timeout=1.0)

    def _line_ended(self, task: asyncio.Task[None]) -> None:
        if not task.cancelled() and task.exception() is not None:
            log.error("%s stopped: %r", task.get_name(), task.exception())

    def _line(self, name: str) -> LineTask | None:
        """The runner of line ``name`` that takes jobs (None: none, or stopped for good)."""
        return None if name in self._ended else self._load.runners.get(name)

    async def stop(self, grace: float = 3.0) -> None:
        """Stop taking jobs, let each line finish its exchange in flight, close the ports."""
        self.stopping = True
        load = self._load
        for runner in {*load.runners.values(), *(r for r, _ in self._tasks.values())}:
            runner.stop()
        if self._tasks:
            await self._end([t for _, t in self._tasks.values()], grace)
        for close in load.closers.values():
            await self._close(close)
        for cleanup in reversed(load.cleanups):
            await self._close(cleanup)

    async def _close(self, close: Callable[[], object] | None) -> None:
        """Call a closer or a cleanup once (a line stopped while the service stops)."""
        if close is not None and not any(c is close for c in self._closed):
            self._closed.append(close)
            result = close()
            if asyncio.iscoroutine(result):
                await result

    def preview(
        self, drive: str, request: pkw.PkwRequest, vtype: ValueType | None = None
    ) -> Preview:
        """``request`` as the drive's carrier would send it now, the bytes a dry run shows
        (where its line is gone, as a new carrier would); LocalProtocolError for a request
        its carrier cannot carry: the one check before anything is sent."""
        entry = self.drives[drive]
        item = Item(request, vtype)
        runner = self._line(entry.line)
        if runner is not None:
            try:
                return runner.preview(drive, item)
            except KeyError:
                pass  # not on its line (yet): a reload under way
        return carrier_for(entry.target).preview(item)

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
            loop.time() + (timeout or self._load.job_timeout),
            fmt,
            future,
            parameter,
            index,
        )
        runner = self._line(entry.line)
        if runner is None:
            future.set_result(JobResult(Cancelled("no such line")))
        else:
            runner.submit(job)
        return future
