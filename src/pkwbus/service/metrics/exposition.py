"""The Prometheus text format (version 0.0.4), rendered a series at a time and cached.

``prometheus_client.generate_latest`` builds a ``Sample`` per series, sorts and
escapes its labels and formats its value at every scrape: about a second for
eight lines of 126 drives with 20 parameters each. Here each series keeps the
text before its value (``name{labels} ``), made once, and its last rendered
line (UTF-8 bytes), made again only when the value changed; a scrape joins the
lines. The service's own counters are :class:`CounterFamily` families (their
text kept until a series changes), the drives' values come from
:mod:`.devices`, and prometheus_client's gauges, counters and histograms are
rendered from their values (:mod:`.native`); another collector's families go
through ``generate_latest``.

The output is the same text ``generate_latest`` makes of the same registry
(labels sorted by name, values as Go prints them, the same escaping): the
collectors below also answer ``collect()`` with the same series, so
``registry.get_sample_value`` and ``generate_latest`` still see them.

:func:`render` hands the event loop back between pieces of text (at most
:data:`CHUNK` lines each; a collector whose work between two pieces is long yields
an empty piece in between) once :data:`TURN_EVERY` seconds of rendering have
passed, so polling keeps its pace while a large configuration is scraped, and a
scrape that finds most pieces kept is not made to wait for turns it does not need.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Protocol, runtime_checkable

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_PLAIN_0_0_4
from prometheus_client.registry import Collector

from pkwbus.service.metrics.native import NativeFamily, native
from pkwbus.service.metrics.textformat import format_value, head, header

__all__ = [
    "CHUNK",
    "CONTENT_TYPE",
    "TURN_EVERY",
    "CounterFamily",
    "Exposed",
    "MetricsRegistry",
    "Series",
    "format_value",
    "head",
    "header",
    "render",
]

CONTENT_TYPE = CONTENT_TYPE_PLAIN_0_0_4
# Lines rendered at most in one piece of text, and seconds of rendering before the
# scrape returns to the event loop.
CHUNK = 500
TURN_EVERY = 0.004


@runtime_checkable
class Exposed(Protocol):
    """A collector that renders its own text (the lines of its families, in order).

    An empty piece is a place where :func:`render` may give the event loop a turn: a
    collector whose work between two pieces of text is long yields one now and then.
    """

    def exposition(self) -> Iterator[bytes]: ...


class _Changes:
    """How many times a family's series changed (``count``: its text is made again only
    then) and how many times a series came, went or became visible (``shown``)."""

    __slots__ = ("count", "shown")

    def __init__(self) -> None:
        self.count = 0
        self.shown = 0


class Series:
    """One counter series: its value, and its line rendered again only after a change.

    ``visible`` is False for a series that has never moved and need not be
    exported at 0; the first increment makes it visible.
    """

    __slots__ = ("_changes", "_line", "_shown", "head", "value", "visible")

    def __init__(self, head: str, visible: bool, changes: _Changes | None = None) -> None:
        self.head = head
        self.value = 0.0
        self.visible = visible
        self._changes = changes if changes is not None else _Changes()
        self._shown: float | None = None
        self._line = b""

    def inc(self, amount: float = 1.0) -> None:
        if amount < 0:
            raise ValueError("a counter only goes up")
        self.value += amount
        changes = self._changes
        if not self.visible:
            self.visible = True
            changes.shown += 1
        changes.count += 1

    def show(self) -> None:
        """Export the series from now on, at its value (0 until it moves)."""
        if not self.visible:
            self.visible = True
            self._changes.shown += 1
        self._changes.count += 1

    def line(self) -> bytes:
        value = self.value
        if value != self._shown:
            self._line = f"{self.head}{format_value(value)}\n".encode()
            self._shown = value
        return self._line


class CounterFamily(Collector):
    """A labelled counter whose series exist at 0 only where asked (``labels(..., zero=True)``).

    A series made without ``zero`` appears at its first increment. The family's
    text is kept until one of its series changes: the fault counters of a
    thousand drives, nearly all at 0, are made once, not at every scrape.
    """

    def __init__(
        self,
        name: str,
        documentation: str,
        labelnames: Sequence[str],
        registry: CollectorRegistry | None = None,
    ) -> None:
        self.name = name
        self.documentation = documentation
        self.labelnames = tuple(labelnames)
        self._series: dict[tuple[str, ...], Series] = {}
        self._header = header(f"{name}_total", documentation, "counter").encode()
        self._changes = _Changes()
        self._pieces: list[bytes] | None = None  # the text, as of ``_seen`` changes
        self._seen = 0
        self._visible: list[Series] = []  # the series exported, as of ``_shown`` changes
        self._shown = -1
        if registry is not None:
            registry.register(self)

    def labels(self, *values: str, zero: bool = False) -> Series:
        """The series of these label values; ``zero``: exported from now on, at 0 until it moves."""
        series = self._series.get(values)
        if series is None:
            if len(values) != len(self.labelnames):
                raise ValueError(f"{self.name}: {len(self.labelnames)} label values expected")
            labels = dict(zip(self.labelnames, values, strict=True))
            series = Series(head(f"{self.name}_total", labels), zero, self._changes)
            self._series[values] = series
            self._changes.count += 1
            self._changes.shown += 1
        elif zero:
            series.show()
        return series

    def forget(self, labels: Mapping[str, str]) -> int:
        """Remove the series whose labels include all of ``labels`` (none when the family
        lacks one of their names); how many went."""
        if not all(k in self.labelnames for k in labels):
            return 0
        at = [(self.labelnames.index(k), v) for k, v in labels.items()]
        gone = [key for key in self._series if all(key[i] == v for i, v in at)]
        for key in gone:
            del self._series[key]
        if gone:
            self._changes.count += 1
            self._changes.shown += 1
        return len(gone)

    def describe(self) -> list[Metric]:
        return [CounterMetricFamily(self.name, self.documentation, labels=self.labelnames)]

    def collect(self) -> Iterator[Metric]:
        family = CounterMetricFamily(self.name, self.documentation, labels=self.labelnames)
        for values, series in list(self._series.items()):
            if series.visible:
                family.add_metric(list(values), series.value)
        yield family

    def exposition(self) -> Iterator[bytes]:
        yield self._header
        pieces = self._pieces
        if pieces is not None and self._seen == self._changes.count:
            yield from pieces
            return
        self._pieces = None  # made again below; a change meanwhile shows at the next scrape
        self._seen = self._changes.count
        if self._shown != self._changes.shown:
            self._shown = self._changes.shown
            self._visible = [s for s in self._series.values() if s.visible]
        pieces = []
        every = self._visible
        for start in range(0, len(every), CHUNK):
            text = b"".join([s.line() for s in every[start : start + CHUNK]])
            pieces.append(text)
            yield text
        self._pieces = pieces


class _Collected:
    def __init__(self, metrics: Iterable[Metric]) -> None:
        self._metrics = list(metrics)

    def collect(self) -> Iterable[Metric]:
        return self._metrics


class MetricsRegistry(CollectorRegistry):
    """A registry that keeps its collectors in order, for :func:`render`.

    Collectors that are :class:`Exposed` render their own text; prometheus_client's
    gauges, counters and histograms are rendered from their values
    (:mod:`pkwbus.service.metrics.native`); any other collector's families go
    through ``generate_latest``.
    """

    def __init__(self) -> None:
        super().__init__()
        # Each collector, in order, and how its text is made: by itself, from its values,
        # or (None) by generate_latest.
        self._ordered: dict[Collector, Exposed | NativeFamily | None] = {}

    def register(self, collector: Collector) -> None:
        super().register(collector)
        self._ordered[collector] = (
            collector if isinstance(collector, Exposed) else native(collector)
        )

    def unregister(self, collector: Collector) -> None:
        super().unregister(collector)
        self._ordered.pop(collector, None)

    def collectors(self) -> list[Collector]:
        """The registered collectors, in order."""
        return list(self._ordered)

    def exposition(self) -> Iterator[bytes]:
        """The text of every family, as pieces to join."""
        for collector in list(self._ordered):
            yield from self.exposition_of(collector)

    def exposition_of(self, collector: Collector) -> Iterator[bytes]:
        """The text of one registered collector's families."""
        way = self._ordered.get(collector)
        if way is not None and not isinstance(way, NativeFamily):
            yield from way.exposition()
            return
        text = way.text() if way is not None else None
        if text is None:
            text = generate_latest(_Collected(collector.collect()))
        yield text


async def render(
    registry: CollectorRegistry, *, clock: Callable[[], float] = time.perf_counter
) -> bytes:
    """The registry's text; a :class:`MetricsRegistry` returns to the loop between two
    pieces once :data:`TURN_EVERY` seconds of ``clock`` have passed since the last turn."""
    if not isinstance(registry, MetricsRegistry):
        return await asyncio.to_thread(generate_latest, registry)
    parts: list[bytes] = []
    turn_at = clock() + TURN_EVERY
    for piece in registry.exposition():
        if piece:
            parts.append(piece)
        if clock() >= turn_at:
            await asyncio.sleep(0)
            turn_at = clock() + TURN_EVERY
    return b"".join(parts)
