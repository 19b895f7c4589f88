"""What the edge node keeps beside its connection: the ``bdSeq`` across restarts, and
the primary host application's STATE (Eclipse Sparkplug 3.0.0, "Primary Host
Application" and "Edge Node Session Establishment").

- ``bdSeq``: the number of the node's last session, in a small file beside the MQTT
  outbox, written whole (a temporary file, flushed, then renamed over the old one), so
  that a host sees a new number after a restart and does not take the will of an old
  session for the new one.
- STATE: ``spBv1.0/STATE/{host_id}``, retained, a JSON object ``{"online": true|false,
  "timestamp": <ms>}``. With a primary host configured, the node publishes NBIRTH only
  while that host is online ([tck-id-message-flow-edge-node-birth-publish-phid-wait]),
  and on its offline ends its session (NDEATH, disconnect) and waits for it to come back.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

__all__ = ["BdSeqFile", "HostState", "bd_seq_path", "state_topic"]

log = logging.getLogger("pkwbus.service.mqtt.sparkplug")


def bd_seq_path(audit_db: Path) -> Path:
    """Where the node's ``bdSeq`` is kept: beside the MQTT outbox (and the audit database)."""
    return audit_db.with_name("sparkplug-bdseq")


def state_topic(host_id: str) -> str:
    return f"spBv1.0/STATE/{host_id}"


class BdSeqFile:
    """The ``bdSeq`` of the node's last session, in ``path`` (None: kept in memory only)."""

    def __init__(self, path: Path | None) -> None:
        self.path = path

    def last(self) -> int:
        """The last session's number, -1 when none was kept or the file is unreadable."""
        if self.path is None:
            return -1
        try:
            found = int(self.path.read_text(encoding="ascii").strip())
        except (OSError, ValueError):
            return -1
        return found if 0 <= found <= 255 else -1

    def keep(self, bd_seq: int) -> None:
        """Write ``bd_seq`` whole; a failure is logged (the session goes on)."""
        if self.path is None:
            return
        temporary = self.path.with_name(self.path.name + ".tmp")
        try:
            with open(temporary, "w", encoding="ascii") as file:
                file.write(f"{bd_seq}\n")
                file.flush()
                os.fsync(file.fileno())
            os.replace(temporary, self.path)
        except OSError as exc:
            log.warning("Sparkplug: the bdSeq could not be kept in %s: %s", self.path, exc)


class HostState:
    """The primary host's latest STATE: ``online`` (None until one came), the newest
    timestamp taken (an older STATE, delivered late, is ignored)."""

    def __init__(self) -> None:
        self.online: bool | None = None
        self.timestamp = -1

    def take(self, payload: bytes) -> bool | None:
        """The host's state after ``payload`` (None: not yet known); a payload that is not
        a STATE is logged and changes nothing."""
        try:
            found = json.loads(payload)
            online, timestamp = found["online"], found["timestamp"]
        except (ValueError, TypeError, KeyError) as exc:
            log.warning("Sparkplug: a STATE that is not {online, timestamp}: %s", exc)
            return self.online
        if not isinstance(online, bool) or not isinstance(timestamp, int):
            log.warning("Sparkplug: a STATE whose online is not true/false or timestamp not ms")
            return self.online
        if timestamp >= self.timestamp:
            self.online, self.timestamp = online, timestamp
        return self.online
