"""From a configuration to a runtime: simulated drives, links, lines, runners, metrics.

A ``sim://PROTOCOL?drives=...`` port starts built-in simulated drives on a
pseudo-terminal; the line then opens that pty through pyserial like any
adapter, so the demo takes the production path.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import prometheus_client

from pkwbus.catalog.description import ParameterDescription, ParameterTable
from pkwbus.link import PortSettings
from pkwbus.link.port import Rs485Mode
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.identity import DescriptionBook
from pkwbus.master.planning.plan import DescribeTarget, DriveSpec, PollSpec
from pkwbus.master.runner import LineRunner
from pkwbus.master.snapshot import Reading, ReadingKey, Snapshot
from pkwbus.master.target import DriveTarget, RecordAccess
from pkwbus.master.wires.profibus.port import FdlPort
from pkwbus.master.wires.profibus.wire import CycleWire, SlaveSpec
from pkwbus.master.wires.serial.port import TelegramPort
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import NAME, DescriptionForm, elements_to_read, form_of
from pkwbus.protocol.pkw.length import AUTO
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.dp.slave import SlaveSetup
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profidrive.parameters import AXES
from pkwbus.protocol.serial.telegram import Protocol
from pkwbus.protocol.values import ParameterRef
from pkwbus.service import config as cfg
from pkwbus.service.assembly.alarm_polls import alarm_parameters
from pkwbus.service.assembly.described import DescriptionSink
from pkwbus.service.assembly.description_file import DescriptionFile
from pkwbus.service.assembly.parameter_table import (
    explicit_layers,
    layers_of,
    parameter_table,
)
from pkwbus.service.assembly.simulated import start_dp_sim, start_sim
from pkwbus.service.config.default_polls import (
    ALARM_EVERY,
    COUNTER_EVERY,
    alarm_polls,
    counter_polls,
    swept_settings,
)
from pkwbus.service.metrics.alarms import AlarmBoard
from pkwbus.service.metrics.devices import DriveInfo, ParameterInfo, SnapshotCollector
from pkwbus.service.metrics.exposition import MetricsRegistry
from pkwbus.service.metrics.instrumentation import LineMetrics, ServiceMetrics, api_metrics
from pkwbus.service.metrics.maintenance import MaintenanceCollector
from pkwbus.service.metrics.trends import Trends
from pkwbus.service.runtime import DriveEntry, Runtime

__all__ = [
    "build_runtime",
    "describe_targets",
    "description_form",
    "port_for",
    "target_for",
]


async def build_runtime(config: cfg.Config, kept: DescriptionFile | None = None) -> Runtime:
    """The runtime of ``config``; ``kept``: the drives' descriptions of earlier runs, stored
    again as drives describe more (None: kept in memory only, for this runtime)."""
    prometheus_client.disable_created_metrics()  # type: ignore[no-untyped-call]
    registry = MetricsRegistry()
    metrics = ServiceMetrics(registry)
    api_metrics(registry)  # the API's counters, exported (at zero) from the start
    snapshot = Snapshot()
    runners: list[LineRunner] = []
    entries: list[DriveEntry] = []
    infos: list[ParameterInfo] = []
    cleanups: list[Callable[[], object]] = []
    counts: dict[str, LineMetrics] = {}
    # Each drive's polls first: the exposition of their values is made before any line,
    # so that every line's metrics are given it (a value is rendered as it lands).
    book = kept.book if kept is not None else DescriptionBook()
    planned = [
        (line, [_drive(line, d, entries, infos, book) for d in line.drives])
        for line in config.lines
    ]
    drives = {
        d.name: DriveInfo(line.name, target_for(line, d).profile) for line, d in config.drives()
    }
    collector = SnapshotCollector(snapshot, drives, infos)
    registry.register(collector)
    registry.register(MaintenanceCollector(snapshot, {n: d.line for n, d in drives.items()}))
    board = AlarmBoard(alarm_parameters(config, entries), registry)
    trends = Trends()

    def landed(key: ReadingKey, reading: Reading) -> None:  # each value, to each observer
        collector.landed(key, reading)
        board.landed(key, reading)
        trends.landed(key, reading)

    descriptions = DescriptionSink({e.name: e for e in entries}, collector, kept)
    for line, specs in planned:
        port = line.port
        if line.sim is not None:
            if isinstance(line, cfg.ProfibusLine):
                port, close = await start_dp_sim(line, line.sim)
            else:
                port, close = await start_sim(line, line.sim)
            cleanups.append(close)
        dialects = {d.name: d.pkw_dialect for d in line.drives}
        uss, dp = line.protocol is Protocol.USS, line.protocol is Protocol.PROFIBUS
        events = metrics.for_line(
            line.name, dialects, landed, uss=uss, dp=dp, descriptions=descriptions
        )
        counts[line.name] = events
        if isinstance(line, cfg.ProfibusLine):
            runners.append(_dp_runner(line, port, specs, snapshot, events))
            continue
        wire = ExchangeWire(port_for(line, port))
        runners.append(
            LineRunner(
                line.name,
                wire,
                specs,
                retries=line.retries,
                snapshot=snapshot,
                observers=[events],
            )
        )
    by_line = {r.name: r for r in runners}
    for line, drive in config.drives():
        if drive.maintenance:  # in maintenance from the start: nothing goes out to it
            by_line[line.name].maintenance(drive.name, True, "configuration")
    runtime = Runtime(runners, entries, snapshot, registry, alarms=board, trends=trends)
    runtime.cleanups.extend(cleanups)
    runtime.counts.update(counts)
    return runtime


def port_for(line: cfg.Line, port: str) -> TelegramPort:
    """The FC/USS line a configuration describes, on ``port``."""
    settings = PortSettings(
        port,
        baudrate=line.baudrate,
        parity=line.parity,
        stopbits=line.stopbits,
        pause=line.pause,
        echo=line.echo,
        low_latency=line.low_latency,
        rs485=Rs485Mode(**line.rs485.model_dump()) if line.rs485 is not None else None,
    )
    return TelegramPort(
        settings,
        Protocol(line.protocol),
        timeout=line.timeout,
        inter_char_timeout=line.inter_char_seconds,
    )


def _dp_runner(
    line: cfg.ProfibusLine,
    port: str,
    specs: list[DriveSpec],
    snapshot: Snapshot,
    events: LineMetrics,
) -> LineRunner:
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
        found, _ = drive.dp.settings()
        if found is None:  # the configuration checked it; a GSD file changed since
            raise ValueError(f"drive {drive.name}: its PROFIBUS settings are not usable")
        resolved.append(found)
    # The slot time: as configured, else one that waits for the slowest slave's GSD MaxTsdr.
    tsdr = [s.gsd.max_tsdr.get(line.baudrate, 0) for s in resolved if s.gsd is not None]
    slot = line.slot_time or dp_timing.default_slot_time(line.baudrate, max(tsdr, default=None))
    dp = FdlPort(settings, line.master_address, slot_time=slot)
    # The watchdog: as configured, else several worst-case cycles and at least a second.
    watchdog = line.watchdog or max(1.0, 10 * dp.slot_time * (line.retries + 1) * len(specs))
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
    wire = CycleWire(dp, slaves, name=line.name)
    return LineRunner(
        line.name, wire, specs, snapshot=snapshot, observers=[events], poll_deadline=deadline,
        retries=line.retries,
    )  # fmt: skip


def target_for(line: cfg.Line, drive: cfg.Drive) -> DriveTarget:
    """Where and how a configured drive is reached."""
    record = None
    if isinstance(drive, cfg.ProfibusDrive) and drive.access == "ds47":
        axis = drive.axis if drive.axis is not None else AXES.get(drive.pkw_dialect.name, 0)
        settings = drive.dp.settings()[0]
        dpv1 = settings.dpv1 if settings is not None else None
        record = RecordAccess(axis, max_data=dpv1.max_data if dpv1 is not None else 240)
    return DriveTarget(
        Protocol(line.protocol),
        drive.address,
        drive.pkw_dialect,
        drive.layout,
        drive.shape,
        line.address_format,
        learn=isinstance(drive, cfg.UssDrive) and drive.pkw_words == AUTO,
        record=record,
    )


def _drive(
    line: cfg.Line,
    drive: cfg.Drive,
    entries: list[DriveEntry],
    infos: list[ParameterInfo],
    book: DescriptionBook | None = None,
) -> DriveSpec:
    target = target_for(line, drive)
    table = parameter_table(drive)
    form = description_form(line, drive)
    polls: list[PollSpec] = []
    units: dict[str, str] = {}
    sources: dict[str, str] = {}

    def add(ref: ParameterRef, every: float, *, layered: bool, only_described: bool = False
            ) -> ParameterRef:  # fmt: skip
        """One poll: labelled by the drive's one name for its parameter ("1613" polls
        16-13), described by the configuration and the catalog (and the drive's own
        description, where it is asked: ``layered``)."""
        ref = table.canonical(ref)
        fmt = table.describe(ref)
        found = layers_of(drive, table, ref)
        polls.append(
            PollSpec(ref.name, ref.index or 0, _read(target, ref, fmt), every, fmt,
                     found if layered else None, described_only=only_described)
        )  # fmt: skip
        units[ref.name] = fmt.unit
        info = _info(line, drive, ref, fmt, found.catalog)
        infos.append(info)
        sources[ref.name] = info.source
        return ref

    for entry in drive.poll:
        add(entry.ref, entry.every, layered=form is not None)
    for ref in alarm_polls(line, drive, {p.request.pnu for p in polls}):
        add(ref, ALARM_EVERY, layered=False)
    counters = [
        add(ref, COUNTER_EVERY, layered=form is not None, only_described=not typed)
        for ref, typed in counter_polls(line, drive)
        if typed or form is not None  # one no document types needs the drive's description
    ]
    _, settings = swept_settings(line, drive)  # described with their limits, for a restore
    describe = describe_targets(target, drive, table, counters, settings) if form else ()
    entries.append(
        DriveEntry(
            drive.name,
            line.name,
            target,
            tuple(polls),
            parameters=table,
            units=units,
            layers=explicit_layers(drive, table),
            pending={t.pnu for t in describe},
            sources=sources,
        )
    )
    return DriveSpec(drive.name, carrier_for(target), tuple(polls), describe, form, book)


def description_form(line: cfg.Line, drive: cfg.Drive) -> DescriptionForm | None:
    """How the drive describes its parameters, when it is asked to (``describe: auto``)."""
    if (drive.describe or line.describe) == "off":
        return None
    return form_of(drive.pkw_dialect)


def describe_targets(
    target: DriveTarget,
    drive: cfg.Drive,
    table: ParameterTable,
    polled: Sequence[ParameterRef] = (),
    settings: Sequence[ParameterRef] = (),
) -> tuple[DescribeTarget, ...]:
    """The polled (``drive.poll`` and ``polled``), writable and swept (``settings``)
    parameters, each once: polled ones for their type, scaling, unit, size and name;
    writable and swept ones also for their limits. The name is not asked where it does
    not fit the PKW block: a PPO's four words, a fixed USS length."""
    wanted: dict[int, tuple[str, bool]] = {}
    for ref in [*(entry.ref for entry in drive.poll), *polled]:
        ref = table.canonical(ref)
        wanted.setdefault(ref.pnu, (ref.name, False))
    for ref in [*drive.writable, *settings]:
        ref = table.canonical(ref)
        wanted[ref.pnu] = (wanted.get(ref.pnu, (ref.name, True))[0], True)
    writable = {table.canonical(ref).pnu for ref in drive.writable}
    # A name of 16 characters fits neither a PPO's four PKW words nor a fixed USS block
    # (data record 47 carries it).
    short = (target.protocol is Protocol.PROFIBUS and target.record is None) or (
        isinstance(drive, cfg.UssDrive) and drive.pkw_words in (3, 4)
    )
    targets = []
    for pnu, (name, limits) in wanted.items():
        elements = tuple(e for e in elements_to_read(limits=limits) if not (short and e == NAME))
        catalog = table.catalog.get(pnu)
        targets.append(DescribeTarget(pnu, name, elements, catalog, pnu in writable))
    return tuple(targets)


def _read(target: DriveTarget, ref: ParameterRef, fmt: ParameterDescription) -> pkw.PkwRequest:
    return pkw.read_parameter(target.dialect, ref.pnu, ref.index, text=fmt.is_text)


def _info(
    line: cfg.Line,
    drive: cfg.Drive,
    ref: ParameterRef,
    fmt: ParameterDescription,
    catalog: ParameterDescription | None,
) -> ParameterInfo:
    given = drive.overrides_for(ref).changes().keys() & {"type", "scale", "conversion"}
    source = "config" if given else ("catalog" if catalog is not None else "none")
    return ParameterInfo(
        line.name,
        drive.name,
        ref.name,
        ref.index or 0,
        ref.pnu,
        fmt.name,
        fmt.unit,
        fmt.vtype.value if fmt.vtype else "raw",
        source,
    )
