"""The composition root of ``pkwbus run``: from a valid configuration to a running
service, and back.

In order: logging; the audit log, its place checked first; the history
database of the drives' own logs; the HTTP address bound; the runtime built
from the configuration (:mod:`.build`) with the watch of the drives' logs
(:mod:`.history`) and its reloader (:mod:`.reload`); the HTTP app over it
(:mod:`pkwbus.service.http.api`);
writes an earlier run left without an outcome marked interrupted; then
:func:`~.serve.serve` until a stop signal. On the way out the drives'
descriptions under way are written, the outcomes kept in memory are stored and
the audit log and the history are closed.

Raises :class:`StartError` (one line) when the audit log's or the history's
place or the HTTP address cannot be used, before any line or the HTTP server
has started.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING

from pkwbus import link
from pkwbus.errors import PkwbusError
from pkwbus.service.assembly.build import assemble
from pkwbus.service.assembly.description_file import DescriptionFile, description_path
from pkwbus.service.assembly.history import remember
from pkwbus.service.assembly.loading import LoadBuilder
from pkwbus.service.assembly.logs import setup_logging
from pkwbus.service.assembly.reload import Reloader
from pkwbus.service.assembly.serve import (
    SPARE_DESCRIPTORS,
    ListenError,
    bind,
    raise_open_files_limit,
    serve,
)
from pkwbus.service.assembly.standby_lines import StandbyLines, etcd_engine
from pkwbus.service.audit.log import AuditError, AuditLog, path_problem
from pkwbus.service.config import Config
from pkwbus.service.history.store import HistoryError, HistoryStore
from pkwbus.service.http.api import build_api
from pkwbus.service.http.connections import ConnectionLimit
from pkwbus.service.runtime import Runtime

if TYPE_CHECKING:
    from pkwbus.service.history.stream import EventStream
    from pkwbus.service.mqtt.output import MqttOutput
    from pkwbus.service.mqtt.sparkplug.node import SparkplugNode
    from pkwbus.service.writes.path import WritePath

__all__ = ["StartError", "open_audit", "open_history", "run_service"]

log = logging.getLogger("pkwbus")  # the service's start-up lines, under the command's name


class StartError(PkwbusError):
    """The service cannot start: its audit log's place or its HTTP address is unusable."""


def run_service(
    config: Config,
    *,
    log_format: str,
    debug: bool = False,
    reread: Callable[[], Config] | None = None,
) -> None:
    """Run the service of ``config`` until SIGTERM or SIGINT; ``reread`` reads its file
    again, for a reload (SIGHUP, POST /api/v1/reload; None: no reload)."""
    setup_logging(log_format, debug=debug)
    if config.mqtt is not None:  # the broker account, before anything is opened
        try:
            config.mqtt.credentials()
        except PkwbusError as exc:
            raise StartError(str(exc)) from None
    audit = open_audit(config)
    history: HistoryStore | None = None
    try:
        history = open_history(config)
        try:
            sock = bind(config.listen.host, config.listen.port)
        except ListenError as exc:
            raise StartError(str(exc)) from None
        link.run(_serve(config, sock, audit, history, reread))
    finally:
        if history is not None:
            history.close()
        audit.close()


def open_audit(config: Config) -> AuditLog:
    """The audit log of a starting service; a place that cannot hold it is a
    :class:`StartError`, never an internal error."""
    problem = path_problem(config.audit_db)
    if problem is not None:
        raise StartError(f"audit_db: {problem}")
    try:
        return AuditLog(config.audit_db)
    except AuditError as exc:
        raise StartError(f"audit_db: {exc}") from None


def open_history(config: Config) -> HistoryStore:
    """The history database of a starting service; a place that cannot hold it is a
    :class:`StartError`."""
    path = config.history_path
    problem = path_problem(path, "the history database")
    if problem is not None:
        raise StartError(f"history_db: {problem}")
    try:
        return HistoryStore(path)
    except HistoryError as exc:
        raise StartError(f"history_db: {exc}") from None


def _mqtt(
    config: Config, runtime: Runtime, stream: EventStream, next_load: LoadBuilder
) -> MqttOutput | None:
    """The MQTT output (None: no ``mqtt:``), one of ``next_load``'s outputs; imported only then
    (the ``mqtt`` extra)."""
    if config.mqtt is None:
        return None
    from pkwbus.service.mqtt.output import attach

    try:
        output = attach(config, runtime, stream)
    except PkwbusError as exc:  # an account named but unset
        raise StartError(str(exc)) from None
    if output is not None:
        _joins(next_load, output)
    return output


def _joins(next_load: LoadBuilder, output: MqttOutput | SparkplugNode) -> None:
    """``output`` one of the outputs' base (kept over reloads), started with the runtime
    before the rest and stopped after everything else (the drives' watchers first)."""

    async def start() -> None:
        output.start()

    next_load.base.append(output)
    next_load.starters.insert(0, start)
    next_load.cleanups.insert(0, output.stop)


def _mqtt_commands(
    config: Config,
    runtime: Runtime,
    mqtt: MqttOutput,
    path: WritePath,
    reloader: Reloader | None,
    next_load: LoadBuilder,
) -> None:
    """MQTT's writes (``writes: allow_list``: the set topics) and Sparkplug B
    (``sparkplug:``), both through the HTTP API's write path."""
    from pkwbus.service.mqtt.sets import take_sets
    from pkwbus.service.mqtt.sparkplug.attach import attach_sparkplug
    from pkwbus.service.mqtt.sparkplug.host import bd_seq_path

    settings = config.mqtt
    assert settings is not None
    if settings.writes == "allow_list":
        take_sets(mqtt.connection, path, settings.prefix)
    try:
        node = attach_sparkplug(settings, runtime, path, metrics=mqtt.metrics,
                                bd_seq_file=bd_seq_path(config.audit_db))  # fmt: skip
    except PkwbusError as exc:  # an account named but unset
        raise StartError(str(exc)) from None
    if node is not None:
        _joins(next_load, node)
    if node is not None and reloader is not None:
        reloader.after.append(node.rebirth)  # the drives' metrics change: births again


async def _serve(
    config: Config,
    sock: socket.socket,
    audit: AuditLog,
    history: HistoryStore,
    reread: Callable[[], Config] | None = None,
) -> None:
    # The drives' descriptions of an earlier run, beside the audit database (read, and
    # written as drives describe more, off the loop).
    kept = await asyncio.to_thread(DescriptionFile, description_path(config.audit_db))
    runtime, parts = await assemble(config, kept)
    # The rest of the load, frozen and swapped in once before the service starts.
    next_load = LoadBuilder(runtime.load, parts.entries)
    next_load.cleanups.insert(0, kept.settled)  # the last: a write under way ends first
    memory = remember(config, runtime, history, next_load)
    mqtt = _mqtt(config, runtime, memory.stream, next_load)
    token = config.write_token()
    limit = ConnectionLimit(config.api.max_connections)

    def apply_api(new: Config) -> None:  # a reloaded file's API settings, at once
        api.set_tokens(new.write_token(), new.read_token())
        if new.api.max_connections != limit.limit:
            limit.limit = new.api.max_connections
            raise_open_files_limit(limit.limit + SPARE_DESCRIPTORS)

    gate = None  # hot standby: the lines start as this instance wins them
    if config.standby is not None:
        gate = StandbyLines(config, runtime, parts, etcd_engine, memory, next_load)
    reloader = None
    if reread is not None:
        reloader = Reloader(config, reread, runtime, parts, memory, api=apply_api, gate=gate)
        if mqtt is not None:
            reloader.after.append(mqtt.drives_changed)
    api = build_api(
        runtime, audit=audit, write_token=token, read_token=config.read_token(), reloader=reloader
    )
    if mqtt is not None:
        _mqtt_commands(config, runtime, mqtt, api.writes, reloader, next_load)
    runtime.swap(next_load.freeze())
    audit_writer = api.audit_writer
    interrupted = await audit_writer.close_interrupted()
    if interrupted:
        log.warning(
            "audit log: %d write(s) had no recorded outcome (the service stopped before"
            " the answer, or could not store it): marked interrupted",
            interrupted,
        )
    host = config.listen.host
    shown = f"[{host}]" if ":" in host else host
    port = sock.getsockname()[1]  # the one the system chose for listen port 0
    log.info("pkwbus: metrics on http://%s:%d/metrics", shown, port)
    log.info("writes %s", "allowed with the token" if token else "refused: no write token is set")
    try:
        await serve(runtime, api.app, sock, limit=limit, on_hangup=api.reloads)
    finally:
        await asyncio.to_thread(audit_writer.save_late)
