"""How busy each line would be: the estimate ``pkwbus check-config`` prints.

One PKW exchange on a line takes::

    (request bytes + response bytes) * bits per character / baud
    + the pause before the request (3.5 character times unless configured)
    + the drive's response delay (5 ms unless the line says response_delay)

An FC parameter telegram is 16 bytes each way; a USS telegram is
``2 * (pkw + pzd) + 4`` bytes (a variable PKW part is counted as 4 words).
A character is 11 bits with the default 8E1 (10 with parity N). Each polled
parameter demands ``1 / every`` exchanges per second; the line's utilisation
is the sum of exchange time times rate. Repeats after missing answers are
not counted: a silent drive costs ``timeout`` per try on top of this.

A PROFIBUS DP line instead cycles its slaves in turn, one Data_Exchange each
per cycle, whatever is polled. The cycle at best is the sum of each slave's
request and answer frames with the idle and reaction times of the bus timing
(:func:`pkwbus.protocol.profibus.fdl.timing.exchange_time`); a USB adapter's latency
adds to each answer. A slave's PKW channel completes at most one job every
:data:`DP_JOB_CYCLES` cycles (the request, then AK 0 before the next one),
so its polls are refreshed at most ``1 / (DP_JOB_CYCLES * cycle)`` times a
second between them; polls that ask for more are warned about. A DP-V1 slave
reached through data record 47 takes its due polls in one request (up to 39),
written in one cycle and read back in the next (at best: a slave not ready
answers the read with "state conflict" and it is read again): each such
cycle carries one MSAC_C1 exchange more, so its parameters/s are the
request's parameters over two of those longer cycles.

The estimate lives with the configuration: it is arithmetic over the
configuration's models (lines, drives, polls, bus timing), done before anything
runs. The running service never asks it, and the master, which plans at run
time from its own poll specs, imports nothing of the service's.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Final

from pkwbus.catalog.logs import logs_of_drive
from pkwbus.link.adapters import DEV, by_id_names, unstable_name
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.ppo import ppo_type
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profidrive.parameters import MAX_PARAMETERS
from pkwbus.protocol.serial import timing
from pkwbus.protocol.serial.telegram import MAX_TELEGRAM
from pkwbus.service.config.catalogs import Catalogs, builtin_catalogs
from pkwbus.service.config.default_polls import (
    ALARM_EVERY,
    COUNTER_EVERY,
    alarm_polls,
    counter_polls,
    sweep_rate,
    swept_settings,
)
from pkwbus.service.config.drive import DriveBase
from pkwbus.service.config.model import Config, Drive, Line
from pkwbus.service.config.profibus import ProfibusDrive
from pkwbus.service.config.profibus_line import ProfibusLine
from pkwbus.service.config.serial import FcDrive, FcLine, UssDrive, UssLine

__all__ = [
    "DEFAULT_RESPONSE_DELAY",
    "DP_JOB_CYCLES",
    "FC_PARAMETER_TELEGRAM",
    "USS_OVERHEAD",
    "USS_VARIABLE_PKW_WORDS",
    "WARN_UTILISATION",
    "LineLoad",
    "catalog_notes",
    "check_config_report",
    "config_load",
    "dp_frame_bytes",
    "dp_line_load",
    "exchange_seconds",
    "line_load",
    "poll_rates",
    "port_warnings",
    "record_seconds",
    "telegram_bytes",
    "watch_rate",
]

DEFAULT_RESPONSE_DELAY: Final = 0.005  # seconds, FC and USS alike
WARN_UTILISATION: Final = 0.8
FC_PARAMETER_TELEGRAM: Final = 16  # bytes: STX LGE ADR PKE IND PWE PCD1 PCD2 BCC
USS_OVERHEAD: Final = 4  # bytes: STX LGE ADR BCC
USS_VARIABLE_PKW_WORDS: Final = 4
DP_JOB_CYCLES: Final = 2  # DP cycles per PKW job at best: the request, then AK 0


@dataclass(frozen=True, slots=True)
class LineLoad:
    """The estimate for one line."""

    line: str
    protocol: Bus
    baudrate: int
    drives: int
    exchanges_per_second: float  # demanded by the polls
    utilisation: float  # fraction of the line's time (1.0 = always busy)
    capacity: float  # exchanges per second if the line did nothing else
    exchange_seconds: dict[str, float] = field(default_factory=dict)  # per drive
    cycle: float | None = None  # PROFIBUS DP: seconds of one cycle through every slave, at best
    warnings: list[str] = field(default_factory=list)
    # PROFIBUS DP: each slave's access (pkw or ds47) and parameters per second at most.
    access: dict[str, tuple[str, float]] = field(default_factory=dict)
    # FC and USS: the share of the line's time the watch of the drives' logs takes, and
    # the sweep of their settings.
    watching: float = 0.0
    sweeping: float = 0.0


def telegram_bytes(line: FcLine | UssLine, drive: FcDrive | UssDrive) -> int:
    """Bytes of one parameter telegram to or from ``drive``, STX to BCC."""
    if isinstance(drive, FcDrive):
        return FC_PARAMETER_TELEGRAM
    pkw = drive.sent_pkw_words if drive.sent_pkw_words is not None else USS_VARIABLE_PKW_WORDS
    return min(2 * (pkw + drive.pzd_words) + USS_OVERHEAD, MAX_TELEGRAM)


def exchange_seconds(line: FcLine | UssLine, drive: FcDrive | UssDrive) -> float:
    """One request and its response, with the pause before and the drive's delay."""
    delay = line.response_delay_seconds
    if delay is None:
        delay = DEFAULT_RESPONSE_DELAY
    wire = timing.wire_time(2 * telegram_bytes(line, drive), line.character_time)
    return wire + line.pause_seconds + delay


def dp_frame_bytes(drive: ProfibusDrive) -> int:
    """A Data_Exchange request (and its answer) carrying the drive's PPO, in bytes."""
    data = bytes(ppo_type(drive.ppo).length)
    frame = fdl.DataFrame(drive.address, 0, fdl.request_fc(fdl.Function.SRD_HIGH), data=data)
    return len(fdl.encode(frame))


def poll_rates(line: Line, drive: Drive) -> list[float]:
    """The reads per second each of the drive's polls asks for: the configured ones, the
    alarm words (``alarms: auto``) and the counters (``counters: auto``) polled by default."""
    rates = [1 / entry.every for entry in drive.poll]
    implicit = alarm_polls(line, drive, {entry.ref.pnu for entry in drive.poll})
    counters = counter_polls(line, drive)
    return rates + [1 / ALARM_EVERY] * len(implicit) + [1 / COUNTER_EVERY] * len(counters)


def watch_rate(line: Line, drive: Drive) -> float:
    """The reads per second the watch of the drive's own logs asks for (``events``): each
    one's change counter or newest entry every ``events_every`` (the sweeps when it changed are
    rare, and not counted)."""
    logs = logs_of_drive(drive.catalog, drive.protocol, drive.pkw_dialect.name)
    if (drive.events or line.events) == "off":
        return 0.0
    return sum(len(log.watch()) for log in logs) / (drive.events_every or line.events_every)


def record_seconds(drive: ProfibusDrive, count: int, baudrate: int) -> float:
    """One MSAC_C1 exchange of a record transfer of ``count`` value reads, on average: the
    write of the request and the read of its response, each in a cycle of its own."""
    request = 4 + 6 * count  # head, then an address per parameter
    response = 4 + 6 * count  # head, then format, count and up to 4 bytes per value

    def frame(data: int) -> int:
        body = bytes(data)
        fc = fdl.request_fc(fdl.Function.SRD_HIGH)
        return len(fdl.encode(fdl.DataFrame(drive.address, 0, fc, 0x33, 0x33, body)))

    write = dp_timing.exchange_time(frame(4 + request), frame(4), baudrate)
    read = dp_timing.exchange_time(frame(4), frame(4 + response), baudrate)
    return (write + read) / 2


def dp_line_load(line: ProfibusLine) -> LineLoad:
    """The DP cycle of a line and how often each slave's polls can really be refreshed."""
    times = {
        d.name: dp_timing.exchange_time(dp_frame_bytes(d), dp_frame_bytes(d), line.baudrate)
        for d in line.drives
    }
    batch = {
        d.name: min(max(len(poll_rates(line, d)), 1), MAX_PARAMETERS)
        for d in line.drives
        if d.access == "ds47"
    }
    cycle = sum(times.values())
    busy = cycle + sum(
        record_seconds(d, batch[d.name], line.baudrate) for d in line.drives if d.name in batch
    )
    per_slave = 1 / (DP_JOB_CYCLES * cycle)  # PKW jobs per second on each slave, at most
    rate = 0.0
    worst = 0.0
    load = LineLoad(
        line=line.name,
        protocol=line.protocol,
        baudrate=line.baudrate,
        drives=len(line.drives),
        exchanges_per_second=0.0,
        utilisation=0.0,
        capacity=per_slave,
        exchange_seconds=times,
        cycle=cycle,
    )
    for drive in line.drives:
        demand = sum(poll_rates(line, drive))
        rate += demand
        if drive.name in batch:  # data record 47: its polls together, two longer cycles each
            most = batch[drive.name] / (DP_JOB_CYCLES * busy)
            load.access[drive.name] = ("ds47", most)
            worst = max(worst, demand / most)
            if demand > most:
                load.warnings.append(
                    f"line {line.name}: drive {drive.name}'s polls ask for {demand:.1f}"
                    f" reads/s; data record 47 carries at most {most:.1f}/s at a DP cycle of"
                    f" {busy * 1000:.1f} ms"
                )
            continue
        load.access[drive.name] = ("pkw", per_slave)
        worst = max(worst, demand / per_slave)
        if demand > per_slave:
            load.warnings.append(
                f"line {line.name}: drive {drive.name}'s polls ask for {demand:.1f} reads/s;"
                f" its PKW channel carries at most {per_slave:.1f}/s at a DP cycle of"
                f" {cycle * 1000:.1f} ms: each of its {len(poll_rates(line, drive))} polled"
                f" parameters is refreshed about every"
                f" {len(poll_rates(line, drive)) / per_slave:.2f} s at best"
            )
    return replace(load, exchanges_per_second=rate, utilisation=worst)


def line_load(line: Line) -> LineLoad:
    """Utilisation, demand and capacity of one line."""
    if line.protocol is Bus.PROFIBUS:
        return dp_line_load(line)
    times = {d.name: exchange_seconds(line, d) for d in line.drives}
    rate = 0.0
    busy = 0.0
    watching = sweeping = 0.0
    for drive in line.drives:
        for every in poll_rates(line, drive):
            rate += every
            busy += times[drive.name] * every
        watching += times[drive.name] * watch_rate(line, drive)
        sweeping += times[drive.name] * sweep_rate(line, drive)
    mean = busy / rate if rate else sum(times.values()) / len(times)
    load = LineLoad(
        line=line.name,
        protocol=line.protocol,
        baudrate=line.baudrate,
        drives=len(line.drives),
        exchanges_per_second=rate,
        utilisation=busy,
        capacity=1 / mean,
        exchange_seconds=times,
        watching=watching,
        sweeping=sweeping,
    )
    load.warnings.extend(_warnings(load))
    return load


def _warnings(load: LineLoad) -> Iterator[str]:
    if load.utilisation + load.watching + load.sweeping > 1:
        yield (
            f"line {load.line}: polls demand {load.exchanges_per_second:.1f} exchanges/s, "
            f"more than the {load.capacity:.1f} the line can carry: polls will run late"
        )
    elif load.utilisation + load.watching + load.sweeping > WARN_UTILISATION:
        yield (
            f"line {load.line}: utilisation {load.utilisation:.0%} is above "
            f"{WARN_UTILISATION:.0%}: little room for writes, reads and repeats"
        )


def config_load(config: Config) -> list[LineLoad]:
    return [line_load(line) for line in config.lines]


def catalog_notes(config: Config, catalogs: Catalogs | None = None) -> list[str]:
    """Polled parameters their drive's catalog lacks: read and exported as raw numbers."""
    found = catalogs or builtin_catalogs()
    notes: list[str] = []
    for i, line in enumerate(config.lines):
        for j, drive in enumerate(line.drives):
            notes.extend(_drive_notes(f"lines[{i}].drives[{j}]", drive, found))
    return notes


def _drive_notes(place: str, drive: DriveBase, catalogs: Catalogs) -> Iterable[str]:
    if drive.catalog is None:
        untyped = [str(p.ref) for p in drive.poll if p.type is None]
        if untyped:
            yield (
                f"{place}: drive {drive.name} has no catalog: "
                f"{', '.join(untyped)} are exported as raw numbers"
            )
        return
    try:
        catalog = catalogs.load(drive.catalog)
    except (LookupError, ValueError) as exc:
        yield f"{place}.catalog: {exc}"
        return
    for k, entry in enumerate(drive.poll):
        if catalog.get(entry.ref.pnu) is None:
            how = (
                "the config's type and scaling apply"
                if entry.type is not None
                else "it is read and exported as its raw number"
            )
            yield f"{place}.poll[{k}]: {entry.ref} is not in catalog {drive.catalog}: {how}"


def port_warnings(line: Line, *, dev: Path = DEV) -> list[str]:
    """A kernel-numbered USB port (``/dev/ttyUSB0``): recommend its stable by-id name."""
    if not unstable_name(line.port):
        return []
    stable = by_id_names(line.port, dev=dev)
    use = (
        f"use {stable[0]}"
        if stable
        else "use its /dev/serial/by-id/... name (pkwbus ports lists them)"
    )
    return [
        f"line {line.name}: port {line.port} is numbered by the kernel in the order it finds "
        f"adapters and may name another adapter after a replug or a reboot: {use}"
    ]


def check_config_report(
    config: Config, catalogs: Catalogs | None = None, *, dev: Path = DEV
) -> list[str]:
    """What ``pkwbus check-config`` prints for a valid configuration, line by line."""
    report = [f"listen {config.listen}, audit log {config.audit_db}"]
    for line, load in zip(config.lines, config_load(config), strict=True):
        if load.cycle is not None:
            report.append(
                f"line {load.line}: profibus at {load.baudrate} baud, {load.drives} slaves,"
                f" DP cycle {load.cycle * 1000:.1f} ms at best ({1 / load.cycle:.0f} cycles/s;"
                f" a USB adapter's latency adds to each answer), {load.exchanges_per_second:.2f}"
                f" polls/s, at most {load.capacity:.1f} PKW jobs/s per slave"
            )
            for drive, (access, most) in load.access.items():
                if access == "ds47":
                    report.append(
                        f"  drive {drive}: parameters through data record 47 (DP-V1), at most"
                        f" {most:.1f} parameters/s (its PKW channel, where it has one: at most"
                        f" {load.capacity:.1f}/s)"
                    )
            if swept := _swept(line, "slave"):
                most = max(sweep_rate(line, d) for d in line.drives)
                report.append(
                    f"{swept}: at most {most / load.capacity:.2%} of a slave's PKW jobs, after"
                    " the polls"
                )
            report.extend(f"WARN {w}" for w in load.warnings)
            report.extend(f"WARN {w}" for w in port_warnings(line, dev=dev))
            continue
        report.append(
            f"line {load.line}: {load.protocol} at {load.baudrate} baud, {load.drives} drives, "
            f"{load.exchanges_per_second:.2f} polls/s, utilisation {load.utilisation:.1%} "
            f"(capacity {load.capacity:.0f} exchanges/s)"
        )
        counters = {d.name: len(counter_polls(line, d))
                    for d in line.drives}  # fmt: skip
        if sum(counters.values()):
            share = sum(load.exchange_seconds[n] * c / COUNTER_EVERY for n, c in counters.items())
            report.append(
                f"  {sum(counters.values())} counter(s) of {sum(1 for c in counters.values() if c)}"
                f" drive(s) polled by default (counters), every {COUNTER_EVERY:.0f} s:"
                f" {share:.2%} of the line's time (in the utilisation)"
            )
        if swept := _swept(line, "drive"):
            report.append(f"{swept}: {load.sweeping:.2%} of the line's time, after the polls")
        watched = sum(1 for d in line.drives if watch_rate(line, d))
        if watched:
            report.append(
                f"  the own logs of {watched} drive(s) watched (events): {load.watching:.2%}"
                " of the line's time, after the polls"
            )
        report.extend(f"WARN {w}" for w in load.warnings)
        report.extend(f"WARN {w}" for w in port_warnings(line, dev=dev))
    report.extend(f"NOTE {n}" for n in catalog_notes(config, catalogs))
    return report


def _swept(line: Line, what: str) -> str:
    """The report's words for the settings swept on ``line`` (empty: none)."""
    swept = [len(swept_settings(line, d)[1]) for d in line.drives if sweep_rate(line, d)]
    if not swept:
        return ""
    return f"  {sum(swept)} setting(s) of {len(swept)} {what}(s) swept (settings)"
