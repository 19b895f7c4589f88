"""One stream of what the drives remember, kept once: the entries of their own logs and
the changes of their settings that nobody audited, stored in the history database and
counted by ``pkwbus_drive_events_total`` (each once, over restarts)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable, Sequence

from prometheus_client import CollectorRegistry, Counter, Gauge

from pkwbus.service.history.store import DriveEvent, HistoryError, HistoryStore

__all__ = ["EVENT_LABELS", "EventStream"]

log = logging.getLogger("pkwbus.service.history")

EVENT_LABELS = ("line", "drive", "kind", "code", "text")


class EventStream:
    """The drives' events as kept in ``store``, counted in ``registry``."""

    def __init__(self, store: HistoryStore, registry: CollectorRegistry) -> None:
        self.store = store
        self.counter = Counter(
            "pkwbus_drive_events",
            "Entries of the drives' own fault and alarm logs, and changes of their settings"
            " that nobody audited, each counted once (also those logged while pkwbus was"
            " not running, found at start)",
            list(EVENT_LABELS),
            registry=registry,
        )
        self.newest = Gauge(
            "pkwbus_drive_event_newest_timestamp_seconds",
            "When pkwbus found the newest entry of this kind in the drive's own log, with its"
            " code and text (0 with empty code and text: none yet); a series per watched"
            " drive and kind from the start",
            list(EVENT_LABELS),
            registry=registry,
        )
        self._newest: dict[tuple[str, str], tuple[str, ...]] = {}  # (drive, kind) -> labels
        self._started = False
        # The (line, drive) pairs of the configuration: what the history holds of others (a
        # drive removed, or moved to another line) is not counted at the start (None: all).
        self.present: frozenset[tuple[str, str]] | None = None
        # Who is told of each new event, the oldest first, as it is counted (MQTT).
        self.listeners: list[Callable[[list[DriveEvent]], None]] = []

    def again(self) -> None:
        """Count afresh at the next start (a reload: the drives and lines may be others, and
        a line or drive gone took its series along): nothing is counted twice."""
        self.counter.clear()
        self.newest.clear()
        self._newest.clear()
        self._started = False

    async def start(self, kinds: Iterable[tuple[str, str, str]] = ()) -> bool:
        """Count what the history already holds (once), and show the newest entry of each
        (line, drive, kind) in ``kinds``; False when the history cannot be read."""
        try:
            if not self._started:
                counts = await asyncio.to_thread(self.store.counts)
                present = self.present
                for labels, n in counts.items():
                    if present is None or (labels[0], labels[1]) in present:
                        self.counter.labels(*labels).inc(n)
                self._started = True
            for line, drive, kind in kinds:
                newest = await asyncio.to_thread(self.store.newest, drive, kind)
                if newest is None:
                    self._show_newest(line, drive, kind, "", "", 0.0)
                else:
                    self._show_newest(line, drive, kind, newest.code, newest.text, newest.seen)
        except HistoryError as exc:
            log.error("%s: the drives' logs and settings are not watched", exc)
            return False
        return True

    async def record(self, events: Sequence[DriveEvent]) -> list[DriveEvent]:
        """Store ``events``; those that were new, each counted once (HistoryError when the
        history cannot store them: nothing is counted)."""
        new = await asyncio.to_thread(self.store.add, events)
        self.count(new)
        return new

    def count(self, new: Sequence[DriveEvent]) -> None:
        """Count ``new``, events stored elsewhere (with what they tell, in one transaction)."""
        for e in reversed(new):  # the oldest first
            self.counter.labels(e.line, e.drive, e.kind, e.code, e.text).inc()
            self._show_newest(e.line, e.drive, e.kind, e.code, e.text, e.seen)
        if new and self.listeners:
            oldest_first = list(reversed(new))
            for listener in self.listeners:
                listener(oldest_first)

    def _show_newest(
        self, line: str, drive: str, kind: str, code: str, text: str, seen: float
    ) -> None:
        labels = (line, drive, kind, code, text)
        old = self._newest.get((drive, kind))
        if old is not None and old != labels:
            with contextlib.suppress(KeyError):
                self.newest.remove(*old)
        self._newest[(drive, kind)] = labels
        self.newest.labels(*labels).set(seen)
