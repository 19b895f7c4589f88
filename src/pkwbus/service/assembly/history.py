"""What the drives remember, watched, put together: which drive has which log and which
settings, the history database, the watchers on the lines' streams
(:mod:`pkwbus.service.history`)."""

from __future__ import annotations

import logging
from collections.abc import Callable

from pkwbus.catalog.alarms import CodeTable, alarm_table
from pkwbus.catalog.logs import logs_of_drive
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.logs import DriveLog
from pkwbus.protocol.values import ParameterRef
from pkwbus.service import config as cfg
from pkwbus.service.assembly.loading import LoadBuilder, change
from pkwbus.service.config.default_polls import swept_settings
from pkwbus.service.config.resolved import description_form
from pkwbus.service.history.setting_reads import Swept
from pkwbus.service.history.settings import SettingsWatcher
from pkwbus.service.history.settings_store import SettingsStore
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.history.stream import EventStream
from pkwbus.service.history.watch import LogWatcher, Watched
from pkwbus.service.runtime import Runtime

__all__ = ["Memory", "logs_of", "remember", "watch_logs", "watch_settings"]

log = logging.getLogger("pkwbus.service.history")


def logs_of(line: cfg.Line, drive: cfg.Drive) -> tuple[DriveLog, ...]:
    """The logs a configured drive's events are read from (none: off, or none known): its
    catalog's, or a DP drive's PROFIdrive fault buffer (:func:`logs_of_drive`)."""
    if (drive.events or line.events) == "off":
        return ()
    return logs_of_drive(drive.catalog, drive.protocol, drive.pkw_dialect.name)


def _codes(catalog: str | None, log: DriveLog) -> CodeTable | None:
    """How the log's codes read in words: its catalog's table of the log's code parameter."""
    table = alarm_table(catalog) if catalog is not None else None
    sweep = log.sweep()
    codes = sweep.next()  # the first round reads the codes
    for read in codes:
        decoder = table.decoder(read.pnu) if table is not None else None
        if isinstance(decoder, CodeTable):
            return decoder
    return None


def watch_logs(
    config: cfg.Config, next_load: LoadBuilder, stream: EventStream
) -> LogWatcher | None:
    """The watcher of every drive whose log is known, on the lines of ``next_load`` (None:
    none); it starts once the lines run and stops after them."""
    watched = []
    for line, drive in config.drives():
        entry = next_load.drives.get(drive.name)
        if entry is None:
            continue
        every = drive.events_every or line.events_every
        dialect = entry.target.dialect
        for found in logs_of(line, drive):
            codes = _codes(drive.catalog, found)
            watched.append(Watched(line.name, drive.name, dialect, found, every, codes))
    if not watched:
        return None
    runners = dict(next_load.runners)
    watcher = LogWatcher(runners, stream, watched, retention=config.history_retention)
    next_load.history = stream.store
    drives, path = len({w.drive for w in watched}), stream.store.path
    log.info("watching %d log(s) of %d drive(s), kept in %s", len(watched), drives, path)
    return watcher


def watch_settings(
    config: cfg.Config,
    runtime: Runtime,
    next_load: LoadBuilder,
    stream: EventStream,
    store: Callable[[], SettingsStore] | None = None,
) -> SettingsWatcher | None:
    """The sweep of every drive's settings (``settings``), on the lines of ``next_load`` (None:
    none are swept); it starts once the lines run and stops after them."""
    swept: list[Swept] = []
    for line in config.lines:
        turn = 0
        for drive in line.drives:
            every, refs = swept_settings(line, drive)
            entry = next_load.drives.get(drive.name)
            if not refs or entry is None:
                continue
            named = []
            for ref in refs:
                try:
                    canonical = entry.canonical(ref)
                except LocalProtocolError:
                    canonical = ref
                named.append(ParameterRef(canonical.pnu, ref.index, canonical.name))
            offset = turn / len(line.drives)
            form = description_form(line, drive)
            swept.append(Swept(line.name, entry, every, named, drive.catalog, form, offset,
                               snapshot=runtime.snapshot))  # fmt: skip
            turn += 1
    if not swept:
        next_load.settings = None  # nor the last load's watcher, stopped: nothing is swept
        return None
    kept = store() if store is not None else SettingsStore(stream.store.path, stream.store.changes)
    runners = dict(next_load.runners)
    watcher = SettingsWatcher(runners, kept, stream, swept, runtime.registry)
    for name in runners:
        watcher.line_state(name, runtime.snapshot.lines.get(name, False))  # a reload's
    next_load.settings = watcher
    log.info("sweeping the settings of %d drive(s), kept in %s", len(swept), kept.path)
    return watcher


class Memory:
    """What the drives remember, watched: their own logs and their settings, both kept in
    the history database and told on one stream of events; watched afresh by a reload."""

    def __init__(self, runtime: Runtime, store: HistoryStore) -> None:
        self.runtime = runtime
        self.stream = EventStream(store, runtime.registry)
        self.logs: LogWatcher | None = None
        self.settings: SettingsWatcher | None = None
        # One store of the settings for every watcher a reload makes: a write that ends
        # while a reload makes the next one moves the baseline the next one loads.
        self._settings_store: SettingsStore | None = None
        self._swept: set[str] = set()  # the drives whose settings the last watcher swept

    def _store(self) -> SettingsStore:
        if self._settings_store is None:
            history = self.stream.store  # its changes counted where the history's are
            self._settings_store = SettingsStore(history.path, history.changes)
        return self._settings_store

    def watch(self, config: cfg.Config, next_load: LoadBuilder) -> None:
        """Watch the drives of ``config`` on the lines of ``next_load`` (the runtime's next load:
        at the start, a reload's, a line's won or lost in hot standby)."""
        self.stream.present = frozenset((line.name, d.name) for line in config.lines
                                        for d in line.drives)  # fmt: skip
        self.logs = watch_logs(config, next_load, self.stream)
        self.settings = watch_settings(config, self.runtime, next_load, self.stream, self._store)
        swept = set(self.settings.swept) if self.settings is not None else set()
        self._unswept(config, next_load, self._swept - swept)
        self._swept = swept
        # Drives and lines that come back, drives identified as other drives: the watchers
        # follow every line's stream, as outputs.
        next_load.watchers = [w for w in (self.logs, self.settings) if w is not None]

    def _unswept(self, config: cfg.Config, next_load: LoadBuilder, drives: set[str]) -> None:
        """The read model told that ``drives``, still on a line, are not swept any more (a
        reload turned their sweep off): what it showed of their last sweep is not current."""
        for line in config.lines:
            runner = next_load.runners.get(line.name)
            for drive in line.drives:
                if drive.name in drives and runner is not None:
                    runner.settings_seen(drive.name, None, None)

    async def start(self) -> None:
        for watcher in (self.logs, self.settings):
            if watcher is not None:
                await watcher.start()

    async def stop(self, *, final: bool = True) -> None:
        """Stop watching: the watchers leave the lines, their gauges leave the registry;
        ``final``: the service stops (not a reload)."""
        self.runtime.unwatch()
        if self.logs is not None:
            await self.logs.stop()
        if self.settings is not None:
            await self.settings.stop()
            self.settings.unregister(self.runtime.registry)
        if final and self._settings_store is not None:
            self._settings_store.close()
            self._settings_store = None
        self.logs = self.settings = None
        self.stream.again()


def remember(
    config: cfg.Config, runtime: Runtime, store: HistoryStore, next_load: LoadBuilder | None = None
) -> Memory:
    """What the drives remember, watched from the runtime's start to its stop: into
    ``next_load`` (None: the runtime's next load, swapped in here)."""
    memory = Memory(runtime, store)
    with change(runtime, next_load) as next_load:
        next_load.history = store
        memory.watch(config, next_load)
        next_load.starters.append(memory.start)
        next_load.cleanups.append(memory.stop)
    return memory
