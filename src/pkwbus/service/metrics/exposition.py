"""The Prometheus text format (version 0.0.4), rendered a series at a time and cached.

``prometheus_client.generate_latest`` builds a ``Sample`` per series, sorts and
escapes its labels and formats its value at every scrape: about a second for
eight lines of 126 drives with 20 parameters each. Here each series keeps the
text before its value (``name{labels} ``), made once, and its last rendered
line, made again only when the value changed; a scrape joins the lines.

The output is the same text ``generate_latest`` makes of the same registry
(labels sorted by name, values as Go prints them, the same escaping): the
collectors below also answer ``collect()`` with the same series, so
``registry.get_sample_value`` and ``generate_latest`` still see them.

:func:`render` hands the event loop back between pieces of text (at most
:data:`CHUNK` lines each, :data:`YIELD_EVERY` characters together, about a
millisecond of work), and wherever a collector yields an empty piece, so
polling keeps its pace while a large configuration is scraped.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Protocol, runtime_checkable

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_PLAIN_0_0_4
from prometheus_client.registry import Collector

__all__ = [
    "CHUNK",
    "CONTENT_TYPE",
    "YIELD_EVERY",
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
# Lines rendered at most in one piece of text, and characters rendered before
# the scrape returns to the event loop: a few milliseconds of work.
CHUNK = 500
YIELD_EVERY = 200_000
_SPECIAL = {"inf": "+Inf", "-inf": "-Inf", "nan": "NaN"}


def format_value(value: float) -> str:
    """A sample value as Go prints it: the text of ``prometheus_client.utils.floatToGoString``."""
    text = repr(float(value))
    dot = text.find(".")
    if dot < 0:  # inf, nan, or an exponent: 1e+16
        return _SPECIAL.get(text, text)
    if dot > 6 and text[0] != "-":  # seven digits before the point: an exponent, as in Go
        mantissa = f"{text[0]}.{text[1:dot]}{text[dot + 1 :]}".rstrip("0.")
        return f"{mantissa}e+{dot - 1:02d}"
    return text


def _escape(value: str) -> str:
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")


def head(name: str, labels: Mapping[str, str]) -> str:
    """The text of a sample line before its value: ``name{a="x",b="y"} ``."""
    if not labels:
        return f"{name} "
    inner = ",".join(f'{k}="{_escape(v)}"' for k, v in sorted(labels.items()))
    return f"{name}{{{inner}}} "


def header(name: str, documentation: str, kind: str) -> str:
    """The ``# HELP`` and ``# TYPE`` lines of a family."""
    doc = documentation.replace("\\", r"\\").replace("\n", r"\n")
    return f"# HELP {name} {doc}\n# TYPE {name} {kind}\n"


@runtime_checkable
class Exposed(Protocol):
    """A collector that renders its own text (the lines of its families, in order).

    An empty piece asks :func:`render` for a turn of the event loop: a collector
    whose work between two pieces of text is long yields one now and then.
    """

    def exposition(self) -> Iterator[str]: ...


class _Changes:
    """How many times a family's series changed: its text is made again only then."""

    __slots__ = ("count",)

    def __init__(self) -> None:
        self.count = 0


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
        self._line = ""

    def inc(self, amount: float = 1.0) -> None:
        if amount < 0:
            raise ValueError("a counter only goes up")
        self.value += amount
        self.visible = True
        self._changes.count += 1

    def show(self) -> None:
        """Export the series from now on, at its value (0 until it moves)."""
        self.visible = True
        self._changes.count += 1

    def line(self) -> str:
        value = self.value
        if value != self._shown:
            self._line = f"{self.head}{format_value(value)}\n"
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
        self._header = header(f"{name}_total", documentation, "counter")
        self._changes = _Changes()
        self._pieces: list[str] | None = None  # the text, as of ``_seen`` changes
        self._seen = 0
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
        return len(gone)

    def describe(self) -> list[Metric]:
        return [CounterMetricFamily(self.name, self.documentation, labels=self.labelnames)]

    def collect(self) -> Iterator[Metric]:
        family = CounterMetricFamily(self.name, self.documentation, labels=self.labelnames)
        for values, series in list(self._series.items()):
            if series.visible:
                family.add_metric(list(values), series.value)
        yield family

    def exposition(self) -> Iterator[str]:
        yield self._header
        pieces = self._pieces
        if pieces is not None and self._seen == self._changes.count:
            yield from pieces
            return
        self._pieces = None  # made again below; a change meanwhile shows at the next scrape
        self._seen = self._changes.count
        pieces = []
        every = list(self._series.values())
        for start in range(0, len(every), CHUNK):
            text = "".join([s.line() for s in every[start : start + CHUNK] if s.visible])
            if text:  # an empty piece would ask render() for a turn of the loop
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

    Collectors that are :class:`Exposed` render their own text; any other
    collector's families go through ``generate_latest`` (the small ones: the
    histogram, build and API counters).
    """

    def __init__(self) -> None:
        super().__init__()
        self._ordered: dict[Collector, None] = {}

    def register(self, collector: Collector) -> None:
        super().register(collector)
        self._ordered[collector] = None

    def unregister(self, collector: Collector) -> None:
        super().unregister(collector)
        self._ordered.pop(collector, None)

    def collectors(self) -> list[Collector]:
        """The registered collectors, in order."""
        return list(self._ordered)

    def exposition(self) -> Iterator[str]:
        """The text of every family, as pieces to join."""
        for collector in list(self._ordered):
            if isinstance(collector, Exposed):
                yield from collector.exposition()
            else:
                text = generate_latest(_Collected(collector.collect()))
                yield text.decode("utf-8")


async def render(registry: CollectorRegistry) -> bytes:
    """The registry's text; a :class:`MetricsRegistry` returns to the loop now and then."""
    if not isinstance(registry, MetricsRegistry):
        return await asyncio.to_thread(generate_latest, registry)
    parts: list[bytes] = []
    size = 0
    for piece in registry.exposition():
        if piece:
            parts.append(piece.encode("utf-8"))
            size += len(piece)
        if not piece or size >= YIELD_EVERY:  # an empty piece asks for a turn
            size = 0
            await asyncio.sleep(0)
    return b"".join(parts)
