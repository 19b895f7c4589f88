"""prometheus_client's own families rendered from their values: the text of
generate_latest, never a stale value, generate_latest itself where it cannot."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Iterator

import pytest
from prometheus_client import Counter, Enum, Gauge, Histogram, Info, Summary, generate_latest
from prometheus_client import metrics as client_metrics

from pkwbus.service.metrics.exposition import MetricsRegistry, render
from pkwbus.service.metrics.native import NativeFamily, native


@pytest.fixture(autouse=True)
def no_created(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """As the service runs (Parts: disable_created_metrics); a test may turn them on."""
    monkeypatch.setattr(client_metrics, "_use_created", False)
    yield


def _text(registry: MetricsRegistry) -> str:
    return asyncio.run(render(registry)).decode()


def _same(registry: MetricsRegistry) -> str:
    text = _text(registry)
    assert text == generate_latest(registry).decode()
    return text


class Families:
    def __init__(self) -> None:
        self.registry = r = MetricsRegistry()
        self.gauge = Gauge("t_gauge", 'A "gauge"\nwith \\ odd help', ["line", "drive"], registry=r)
        self.plain = Gauge("t_plain", "An unlabelled gauge", registry=r)
        self.counter = Counter("t_events", "A counter", ["kind"], registry=r)
        self.plain_counter = Counter("t_plain_events", "Unlabelled", registry=r)
        self.histogram = Histogram("t_seconds", "A histogram", ["line"], registry=r,
                                   buckets=(0.01, 0.1, 1.0))  # fmt: skip
        self.negative = Histogram("t_offset", "Negative bounds: no sum", registry=r,
                                  buckets=(-1.0, 0.0, 1.0))  # fmt: skip


def test_gauges_counters_and_histograms_are_rendered_natively_as_generate_latest() -> None:
    f = Families()
    assert all(
        isinstance(native(c), NativeFamily)
        for c in (f.gauge, f.plain, f.counter, f.plain_counter, f.histogram, f.negative)
    )
    _same(f.registry)  # nothing yet: headers, the unlabelled series at 0
    f.gauge.labels("l1", 'Motor "A" \\ 1\nÜberlast').set(3.5)
    f.gauge.labels("l1", "b").set(-0.0)
    f.plain.set(1e22)
    f.counter.labels("timeout").inc(2)
    f.plain_counter.inc(0.25)
    f.histogram.labels("l1").observe(0.05)
    f.histogram.labels("l2").observe(5.0)
    f.negative.observe(-3.0)
    first = _same(f.registry)
    assert _same(f.registry) == first
    for value in (0.0, -0.0, math.nan, math.inf, -math.inf, 12345678.9, 1e-7, 0.0):
        f.gauge.labels("l1", "b").set(value)  # a value of the other sign of zero, NaN
        f.plain.set(value)
        assert _text(f.registry) == generate_latest(f.registry).decode(), value
    f.histogram.labels("l1").observe(0.5)
    f.counter.labels("busy").inc()
    _same(f.registry)
    f.gauge.remove("l1", "b")  # a series gone, then back as a new child at 0
    _same(f.registry)
    f.gauge.labels("l1", "b")
    f.histogram.clear()
    _same(f.registry)


def test_a_value_that_changed_is_never_shown_stale() -> None:
    f = Families()
    series = [f.gauge.labels("l1", f"d{n}") for n in range(50)]
    for n, gauge in enumerate(series):
        gauge.set(n)
    _same(f.registry)
    for n in range(3):  # the same series, one value after another: each shown at once
        series[17].set(1000.0 + n)
        f.counter.labels("x").inc()
        f.histogram.labels("l1").observe(0.001)
        text = _same(f.registry)
        assert f't_gauge{{drive="d17",line="l1"}} {1000.0 + n}\n' in text
        assert f't_events_total{{kind="x"}} {n + 1.0}\n' in text
        assert f't_seconds_bucket{{le="0.01",line="l1"}} {n + 1.0}\n' in text


def test_an_unchanged_family_is_not_made_again(monkeypatch: pytest.MonkeyPatch) -> None:
    f = Families()
    for n in range(20):
        f.gauge.labels("l1", f"d{n}").set(n)
    family = native(f.gauge)
    assert family is not None
    first = family.text()
    made = 0
    lines = NativeFamily._lines

    def counting(self: NativeFamily, heads: tuple[str, ...], values: tuple[float, ...]) -> bytes:
        nonlocal made
        made += 1
        return lines(self, heads, values)

    monkeypatch.setattr(NativeFamily, "_lines", counting)
    assert family.text() is first
    f.gauge.labels("l1", "d3").set(3.0)  # the same value again: the same text
    assert family.text() is first and made == 0
    f.gauge.labels("l1", "d3").set(4.0)
    assert family.text() != first and made == 1  # one series made again, not twenty


def test_what_it_cannot_render_goes_to_generate_latest(monkeypatch: pytest.MonkeyPatch) -> None:
    f = Families()
    Summary("t_summary", "A summary", registry=f.registry).observe(2.0)
    Info("t_build", "An info", registry=f.registry).info({"version": "1"})
    Enum("t_state", "An enum", states=["a", "b"], registry=f.registry).state("b")
    f.gauge.labels("l1", "fn").set_function(lambda: 42.0)  # a gauge given a function
    f.counter.labels("x").inc()
    f.histogram.labels("l1").observe(0.2)
    text = _same(f.registry)
    assert 't_gauge{drive="fn",line="l1"} 42.0\n' in text
    monkeypatch.setattr(client_metrics, "_use_created", True)  # _created samples: theirs
    assert native(f.counter) is not None and native(f.counter).text() is None  # type: ignore[union-attr]
    text = _same(f.registry)
    assert "t_events_created" in text and "t_seconds_created" in text


def test_names_outside_the_legacy_ones_are_left_to_generate_latest() -> None:
    """generate_latest escapes them (``t.dot`` is printed ``t_dot``): its text stands."""
    registry = MetricsRegistry()
    dotted = Gauge("t.dot", "A dotted name", ["line"], registry=registry)
    accented = Gauge("t_accent", "An accented label name", ["lïne"], registry=registry)
    assert native(dotted) is None and native(accented) is None
    dotted.labels("a").set(1)
    accented.labels("a").set(2)
    text = _same(registry)
    assert 't_dot{line="a"} 1.0\n' in text and 't_accent{l_ne="a"} 2.0\n' in text


def test_a_series_given_a_function_after_a_scrape_shows_the_function_s_value() -> None:
    f = Families()
    series = [f.gauge.labels("l1", f"d{n}") for n in range(30)]
    for n, gauge in enumerate(series):
        gauge.set(n)
    _same(f.registry)
    series[29].set_function(lambda: 4242.0)  # the last series: the values as they were
    assert 't_gauge{drive="d29",line="l1"} 4242.0\n' in _same(f.registry)
