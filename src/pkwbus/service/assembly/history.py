"""The watch of the drives' own logs, put together: which drive has which log, the history
database, the watcher on the lines' streams (:mod:`pkwbus.service.history`)."""

from __future__ import annotations

import logging

from pkwbus.catalog.alarms import CodeTable, alarm_table
from pkwbus.catalog.logs import log_of_catalog
from pkwbus.master.runner import LineRunner
from pkwbus.protocol.logs import DriveLog
from pkwbus.service import config as cfg
from pkwbus.service.history.store import HistoryStore
from pkwbus.service.history.watch import LogWatcher, Watched
from pkwbus.service.runtime import Runtime

__all__ = ["log_of", "watch_logs"]

log = logging.getLogger("pkwbus.service.history")


def log_of(line: cfg.Line, drive: cfg.Drive) -> DriveLog | None:
    """The log a configured drive's events are read from (None: off, or none known)."""
    if (drive.events or line.events) == "off":
        return None
    return log_of_catalog(drive.catalog)


def _codes(catalog: str, log: DriveLog) -> CodeTable | None:
    """How the log's codes read in words: its catalog's table of the log's code parameter."""
    table = alarm_table(catalog)
    sweep = log.sweep()
    codes = sweep.next()  # the first round reads the codes
    for read in codes:
        decoder = table.decoder(read.pnu) if table is not None else None
        if isinstance(decoder, CodeTable):
            return decoder
    return None


def watch_logs(config: cfg.Config, runtime: Runtime, store: HistoryStore) -> LogWatcher | None:
    """The watcher of every drive whose log is known, on the runtime's lines (None: none);
    it starts once the lines run and stops after them."""
    watched = []
    for line, drive in config.drives():
        found = log_of(line, drive)
        entry = runtime.drives.get(drive.name)
        if found is None or entry is None or drive.catalog is None:
            continue
        every = drive.events_every or line.events_every
        dialect = entry.target.dialect
        codes = _codes(drive.catalog, found)
        watched.append(Watched(line.name, drive.name, dialect, found, every, codes))
    if not watched:
        return None
    runners = dict(runtime.runners)
    watcher = LogWatcher(runners, store, watched, runtime.registry,
                         retention=config.history_retention)  # fmt: skip
    for runner in runners.values():
        if isinstance(runner, LineRunner):
            runner.observers.append(watcher)  # drives and lines that come back
    runtime.history = store
    runtime.starters.append(watcher.start)
    runtime.cleanups.append(watcher.stop)
    log.info("watching the logs of %d drive(s), kept in %s", len(watched), store.path)
    return watcher
