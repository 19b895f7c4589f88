"""prometheus_client's own families (``Gauge``, ``Counter``, ``Histogram``), rendered
from their series' values as ``generate_latest`` renders them, without its work per
sample.

``generate_latest`` builds a ``Sample`` per series, then escapes and sorts its labels
and formats its value, at every scrape: some 10 µs a series, 10 ms at plant scale for
the drives' log and sweep gauges alone (a series per drive). Here each series keeps
the text before its value (made once) and its line; the values are read at every
scrape and a line is made again when its value is another, so a value is never shown
stale.

A family this cannot render as ``generate_latest`` does - of another type, a gauge set
by a function, a counter or histogram while ``_created`` samples are exported, a name
Prometheus's legacy names exclude - is left to ``generate_latest``: :func:`native`
returns None, or :meth:`NativeFamily.text` does.
"""

from __future__ import annotations

import math
import re
from array import array
from typing import Any

from prometheus_client import Counter, Gauge, Histogram
from prometheus_client import metrics as client_metrics
from prometheus_client.registry import Collector
from prometheus_client.values import MutexValue

from pkwbus.service.metrics.textformat import format_value, head, header

__all__ = ["NativeFamily", "native"]

# Names that generate_latest prints as they are (valid legacy names: no escaping).
_NAME = re.compile(r"[a-zA-Z_:][a-zA-Z0-9_:]*")
_LABEL = re.compile(r"[a-zA-Z_][a-zA-Z0-9_]*")
_TYPES: dict[type, str] = {Gauge: "gauge", Counter: "counter", Histogram: "histogram"}


class _Shown:
    """A series as last rendered: its child, the text before each of its values, the
    values and their lines."""

    __slots__ = ("child", "heads", "text", "values")

    def __init__(self, child: Any, heads: tuple[str, ...]) -> None:
        self.child = child
        self.heads = heads
        self.values: tuple[float, ...] | None = None  # a histogram's: its buckets and sum
        self.text = b""


def _given_a_function(item: tuple[tuple[str, ...], Any]) -> bool:
    """Whether a gauge's series was given a function (``set_function``): its samples are
    the function's."""
    return "_child_samples" in vars(item[1])


def _same(old: tuple[float, ...] | None, new: tuple[float, ...]) -> bool:
    """Whether ``new`` prints as ``old`` did: equal, and no zero of the other sign."""
    if old != new or old is None:
        return False
    signs = zip(old, new, strict=True)
    return all(a != 0 or math.copysign(1.0, a) == math.copysign(1.0, b) for a, b in signs)


def native(collector: Collector) -> NativeFamily | None:
    """The renderer of a prometheus_client ``Gauge``, ``Counter`` or ``Histogram``
    (the family itself, not one of its children); None for any other collector."""
    kind = _TYPES.get(type(collector))
    if kind is None:
        return None
    metric: Any = collector
    names = (*metric._labelnames, *(("le",) if kind == "histogram" else ()))
    if metric._labelvalues or not _NAME.fullmatch(metric._name):
        return None
    if not all(_LABEL.fullmatch(n) for n in names):
        return None
    return NativeFamily(metric, kind)


class NativeFamily:
    """The text of one prometheus_client family, its series' lines kept between scrapes."""

    def __init__(self, metric: Gauge | Counter | Histogram, kind: str) -> None:
        family = next(iter(metric.describe()))
        self._metric: Any = metric
        self._kind = kind
        self._name = family.name
        self._labelnames: tuple[str, ...] = tuple(self._metric._labelnames)
        shown = f"{family.name}_total" if kind == "counter" else family.name
        self._header = header(shown, family.documentation, kind).encode()
        self._shown: dict[tuple[str, ...], _Shown] = {}
        # The last text, the series and the bits of the values it was made of.
        self._text: bytes | None = None
        self._items: list[tuple[tuple[str, ...], Any]] = []
        self._values = b""

    def text(self) -> bytes | None:
        """The family's text now; None when ``generate_latest`` is to make it."""
        metric = self._metric
        if self._kind != "gauge" and client_metrics._use_created:
            return None  # the _created samples, a family of their own: generate_latest's
        if self._labelnames:
            with metric._lock:
                items = list(metric._metrics.items())
        else:
            items = [((), metric)]
        if self._kind == "gauge" and any(map(_given_a_function, items)):
            return None  # a gauge given a function: its samples are the function's
        if self._kind == "histogram":
            numbers = [(*(b.get() for b in c._buckets), c._sum.get()) for _, c in items]
            now = array("d", [v for n in numbers for v in n]).tobytes()
        else:
            # Each series' value as its ``get()`` reads it (a float read whole), without a
            # lock taken and released per series.
            plain = [c._value for _, c in items]
            if all(type(v) is MutexValue for v in plain):
                singles = [v._value for v in plain]
            else:
                singles = [v.get() for v in plain]
            now = array("d", singles).tobytes()
            # The same series with the same values, bit for bit: the same text.
            if self._text is not None and now == self._values and items == self._items:
                return self._text
            numbers = [(v,) for v in singles]
        if self._text is not None and now == self._values and items == self._items:
            return self._text
        before = self._shown
        after: dict[tuple[str, ...], _Shown] = {}
        parts = [self._header]
        for (values, child), number in zip(items, numbers, strict=True):
            shown = before.get(values)
            if shown is None or shown.child is not child:
                shown = _Shown(child, self._heads(values, child))
            after[values] = shown
            if not _same(shown.values, number):
                shown.values = number
                shown.text = self._lines(shown.heads, number)
            parts.append(shown.text)
        self._shown = after
        self._items, self._values = items, now
        self._text = b"".join(parts)
        return self._text

    def _heads(self, values: tuple[str, ...], child: Any) -> tuple[str, ...]:
        labels = dict(zip(self._labelnames, values, strict=True))
        name = self._name
        if self._kind == "counter":
            return (head(f"{name}_total", labels),)
        if self._kind == "gauge":
            return (head(name, labels),)
        bounds = child._upper_bounds
        heads = [head(f"{name}_bucket", {**labels, "le": format_value(b)}) for b in bounds]
        heads.append(head(f"{name}_count", labels))
        if bounds[0] >= 0:  # as prometheus_client has it: no sum when a bound is negative
            heads.append(head(f"{name}_sum", labels))
        return tuple(heads)

    def _lines(self, heads: tuple[str, ...], values: tuple[float, ...]) -> bytes:
        """A series' lines: one value; or a histogram's buckets (counted up), count, sum."""
        if self._kind != "histogram":
            return f"{heads[0]}{format_value(values[0])}\n".encode()
        lines = []
        total = 0.0
        for h, count in zip(heads, values[:-1], strict=False):
            total += count
            lines.append(f"{h}{format_value(total)}\n")
        lines.append(f"{heads[len(values) - 1]}{format_value(total)}\n")
        if len(heads) > len(values):
            lines.append(f"{heads[-1]}{format_value(values[-1])}\n")
        return "".join(lines).encode()
