"""From a configuration to a runtime: simulated drives, links, lines, runners, metrics.

A ``sim://PROTOCOL?drives=...`` port starts built-in simulated drives on a
pseudo-terminal; the line then opens that pty through pyserial like any
adapter, so the demo takes the production path.

:class:`Parts` is what the lines of a runtime share (the registry, the
snapshot, the collectors of values, alarms and trends); it builds a line and
shows its drives, and forgets a drive or a line again (a reload,
:mod:`pkwbus.service.assembly.reload`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import prometheus_client

from pkwbus.catalog import dp_settings
from pkwbus.link import Fence, PortSettings
from pkwbus.link.port import Rs485Mode
from pkwbus.master.events import Observer, Outputs
from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.master.planning.plan import DriveSpec, HealthChanged
from pkwbus.master.runner import LineRunner
from pkwbus.master.snapshot import Snapshot
from pkwbus.master.snapshot_writer import SnapshotWriter
from pkwbus.master.wires.profibus.port import FdlPort
from pkwbus.master.wires.profibus.wire import CycleWire, SlaveSpec
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.dp.slave import Answer, SlaveSetup
from pkwbus.protocol.profibus.fdl import DataFrame
from pkwbus.service import config as cfg
from pkwbus.service.assembly.described import DescriptionSink
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.assembly.drive_plans import plan_drive
from pkwbus.service.assembly.loading import LoadBuilder
from pkwbus.service.assembly.simulated import start_dp_sim, start_sim
from pkwbus.service.config.resolved import port_for
from pkwbus.service.metrics.alarms import AlarmCollector
from pkwbus.service.metrics.devices import DriveInfo, ParameterInfo, SnapshotCollector
from pkwbus.service.metrics.exposition import MetricsRegistry
from pkwbus.service.metrics.forget import forget_series
from pkwbus.service.metrics.instrumentation import LineMetrics, ServiceMetrics, api_metrics
from pkwbus.service.metrics.maintenance import MaintenanceCollector
from pkwbus.service.metrics.service_metrics import ConfigMetrics
from pkwbus.service.metrics.standby import MasterCollector
from pkwbus.service.metrics.trends import Trends
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = [
    "BuiltLine",
    "LinePlan",
    "Parts",
    "assemble",
    "build_runtime",
]


@dataclass
class LinePlan:
    """A configured line's drives as planned: the master's specs, the service's entries and
    the info series of their polled parameters."""

    line: cfg.Line
    specs: list[DriveSpec]
    entries: list[DriveEntry]
    infos: list[ParameterInfo]

    def infos_of(self, drive: str) -> list[ParameterInfo]:
        return [i for i in self.infos if i.drive == drive]


@dataclass
class BuiltLine:
    """A line ready to run: its runner, its counters, and what closes its simulated drives."""

    runner: LineRunner[Any, Any]  # of its bus's requests and answers
    counts: LineMetrics
    close: Callable[[], object] | None = None


class Parts:
    """What the lines of one runtime share, and how a line or a drive joins or leaves it."""

    def __init__(self, kept: DescriptionFile | None = None) -> None:
        prometheus_client.disable_created_metrics()  # type: ignore[no-untyped-call]
        self.registry = registry = MetricsRegistry()
        self.metrics = ServiceMetrics(registry)
        api_metrics(registry)  # the API's counters, exported (at zero) from the start
        self.config_metrics = ConfigMetrics(registry)  # the configuration, loaded now
        self.snapshot = snapshot = Snapshot()
        self.kept = kept
        self.book = kept.book if kept is not None else DescriptionBook()
        self.entries: dict[str, DriveEntry] = {}  # the runtime's drives, by name
        self.counts: dict[str, LineMetrics] = {}  # each line's counters
        self._down: dict[str, SnapshotWriter] = {}  # the writers of lines that cannot start
        # Each PROFIBUS line's slaves' settings as built (their GSD files as read then).
        self.resolved: dict[str, tuple[object, ...]] = {}
        self.line_of: dict[str, str] = {}
        self.collector = SnapshotCollector(snapshot, {}, [])
        registry.register(self.collector)
        registry.register(MaintenanceCollector(snapshot, self.line_of))
        registry.register(AlarmCollector(snapshot, self.line_of))
        self.trends = Trends()
        self.descriptions = DescriptionSink(self.entries, self.collector, kept)
        # What every line's stream goes to besides its own counters: one list, given to
        # each runner at its construction; the drives' watchers join it by one swap.
        self.base: tuple[Observer, ...] = (self.collector, self.trends, self.descriptions)
        self.outputs = Outputs(self.base)
        # Hot standby: each line's fence, given to its port (None: always open).
        self.fence_of: Callable[[str], Fence] | None = None
        # The configured lines' names, in order (pkwbus_line_master; a reload sets them).
        self.lines: list[str] = []

    def plan(self, line: cfg.Line) -> LinePlan:
        entries: list[DriveEntry] = []
        infos: list[ParameterInfo] = []
        specs = [plan_drive(line, d, entries, infos, self.book) for d in line.drives]
        return LinePlan(line, specs, entries, infos)

    def show(self, plan: LinePlan, drives: set[str] | None = None) -> None:
        """The plan's drives (those named in ``drives``, all when None) into the runtime's
        drives and metrics: their values are exported as they land."""
        line = plan.line
        entries = [e for e in plan.entries if drives is None or e.name in drives]
        for entry in entries:
            self.entries[entry.name] = entry
            self.line_of[entry.name] = line.name
            info = DriveInfo(line.name, entry.target.profile)
            self.collector.add_drive(entry.name, info, plan.infos_of(entry.name))

    def forget(self, line: str, drive: str | None = None) -> None:
        """Everything the metrics and the runtime show of ``drive`` (of every drive of
        ``line`` when None), and of the line itself then."""
        gone = [n for n, at in self.line_of.items() if at == line and drive in (None, n)]
        for name in gone:
            self.entries.pop(name, None)
            self.line_of.pop(name, None)
            self.collector.forget_drive(name)
            self.trends.forget(name)
        if drive is None:
            forget_series(self.registry, line=line)
            self.resolved.pop(line, None)
            down = self._down.pop(line, None)
            if down is not None:
                down.forget_line()
        else:
            forget_series(self.registry, line=line, drive=drive)

    def down(self, plan: LinePlan) -> None:
        """A line shown (its drives) that could not start: down, as its alerts must see; its
        writer tells the read model so until the line is forgotten."""
        name = plan.line.name
        writer = self._down[name] = SnapshotWriter(name, plan.specs, self.snapshot)
        writer.apply([HealthChanged(s.name, False) for s in plan.specs])

    async def build(self, plan: LinePlan) -> BuiltLine:
        """The runner of a planned line, its simulated drives started where it has them."""
        line, specs = plan.line, plan.specs
        port, close = line.port, None
        if line.sim is not None:
            if isinstance(line, cfg.ProfibusLine):
                port, close = await start_dp_sim(line, line.sim)
            else:
                port, close = await start_sim(line, line.sim)
        fence = self.fence_of(line.name) if self.fence_of is not None else None
        dialects = {d.name: d.pkw_dialect for d in line.drives}
        uss, dp = line.protocol is Bus.USS, line.protocol is Bus.PROFIBUS
        counts = self.metrics.for_line(line.name, dialects, uss=uss, dp=dp)
        self.counts[line.name] = counts
        runner: LineRunner[Any, Any]
        try:
            if isinstance(line, cfg.ProfibusLine):
                self.resolved[line.name] = tuple(d.dp.settings()[0] for d in line.drives)
                runner = _dp_runner(line, port, specs, self.snapshot, [counts, self.outputs], fence)
            else:
                telegrams = port_for(line, port, fence)
                runner = LineRunner(
                    line.name, telegrams, ExchangeWire(telegrams.timeout), specs,
                    retries=line.retries, snapshot=self.snapshot, observers=[counts, self.outputs],
                )  # fmt: skip
        except BaseException:
            if close is not None:
                await close()
            raise
        for drive in line.drives:
            if drive.maintenance:  # in maintenance from the start: nothing goes out to it
                runner.maintenance(drive.name, True, "configuration")
        return BuiltLine(runner, counts, close)


async def build_runtime(config: cfg.Config, kept: DescriptionFile | None = None) -> Runtime:
    """The runtime of ``config``; ``kept``: the drives' descriptions of earlier runs, stored
    again as drives describe more (None: kept in memory only, for this runtime)."""
    return (await assemble(config, kept))[0]


async def assemble(
    config: cfg.Config, kept: DescriptionFile | None = None
) -> tuple[Runtime, Parts]:
    """The runtime of ``config`` and the parts its lines share (for a reload). In hot
    standby no line is built here: each starts when this instance wins it
    (:mod:`.standby_lines`)."""
    parts = Parts(kept)
    parts.lines = [line.name for line in config.lines]
    here = config.lines if config.standby is None else []
    # Each drive's polls first: the exposition of their values is made before any line,
    # so that every line's metrics are given it (a value is rendered as it lands).
    plans = [parts.plan(line) for line in here]
    for plan in plans:
        parts.show(plan)
    built = [await parts.build(plan) for plan in plans]
    next_load = LoadBuilder(drives=parts.entries)
    next_load.base = list(parts.base)
    for b in built:
        next_load.runners[b.runner.name] = b.runner
        if b.close is not None:
            next_load.closers[b.runner.name] = b.close
    runtime = Runtime(
        parts.snapshot, parts.registry, next_load.freeze(), trends=parts.trends,
        outputs=parts.outputs,
    )  # fmt: skip
    parts.registry.register(MasterCollector(lambda: parts.lines, lambda: runtime.masters))
    return runtime, parts


def _dp_runner(
    line: cfg.ProfibusLine,
    port: str,
    specs: list[DriveSpec],
    snapshot: Snapshot,
    outputs: list[Observer],
    fence: Fence | None = None,
) -> LineRunner[DataFrame, Answer]:
    """The DP master of a ``protocol: profibus`` line: its slaves' Set_Prm and Chk_Cfg data."""
    settings = PortSettings(
        port,
        baudrate=line.baudrate,
        parity="E",
        low_latency=line.low_latency,
        rs485=Rs485Mode(**line.rs485.model_dump()) if line.rs485 is not None else None,
    )
    resolved = []
    for drive in line.drives:
        found, problems = drive.dp.settings()
        if found is None:  # the configuration checked it; a GSD file changed since
            why = "; ".join(f"{place}: {text}" if place else text for place, text in problems)
            raise ValueError(f"drive {drive.name}: its PROFIBUS settings are not usable: {why}")
        resolved.append(found)
    slot = dp_settings.slot_time(line.baudrate, line.slot_time, (s.gsd for s in resolved))
    # The line's master: it clears its slaves before its port closes.
    dp = FdlPort(settings, line.master_address, slot_time=slot, fence=fence, clear_on_close=True)
    watchdog = dp_settings.watchdog(slot, line.retries, len(specs), line.watchdog)
    slaves = []
    for drive, spec, found in zip(line.drives, specs, resolved, strict=True):
        parameters = dp_services.Parameters(
            found.ident, dp_services.watchdog_factors(watchdog), user_prm=found.user_prm
        )
        setup = SlaveSetup(
            drive.address, line.master_address, parameters, found.cfg, line.retries,
            dpv1=found.dpv1,
        )  # fmt: skip
        slaves.append(SlaveSpec(spec, setup, found.ppo))
    # A job may take the cycles of every slave a few times over, and a restart of its slave.
    deadline = max(2.0, 20 * dp.slot_time * len(specs))
    wire = CycleWire(slaves, name=line.name)
    return LineRunner(
        line.name, dp, wire, specs, snapshot=snapshot, observers=outputs, poll_deadline=deadline,
        retries=line.retries,
    )  # fmt: skip
