"""The /metrics renderer: the same text as prometheus_client, valid for promtool, in pieces."""

from __future__ import annotations

import asyncio
import math
import shutil
import subprocess

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from prometheus_client import generate_latest
from prometheus_client import metrics as client_metrics
from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.utils import floatToGoString

from pkwbus.master.events import Exchanged, Outputs, Overrun, ValueLanded
from pkwbus.master.planning.answers import ErrorKind
from pkwbus.master.planning.jobs import JobKind, JobResult
from pkwbus.master.planning.outcomes import Rejected, TimedOut
from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import DriveState, Snapshot
from pkwbus.protocol.pkw.dialects import FC
from pkwbus.protocol.pzd import Profile
from pkwbus.service.metrics import devices, exposition
from pkwbus.service.metrics.devices import DriveInfo, ParameterInfo, SnapshotCollector
from pkwbus.service.metrics.exposition import MetricsRegistry, format_value, render
from pkwbus.service.metrics.instrumentation import LineMetrics, ServiceMetrics, api_metrics

PROMTOOL = shutil.which("promtool") or "/usr/bin/promtool"
# Label values a configuration may bring: quotes, backslashes, a newline, non-ASCII.
ODD = 'Motor "A" \\ 1\nÜberlast'


class Plant:
    """A registry as build_runtime makes it: service counters, API counters, snapshot."""

    def __init__(
        self, lines: int = 2, drives: int = 3, parameters: int = 4, *, landed: bool = False
    ) -> None:
        self.registry = MetricsRegistry()
        self.snapshot = Snapshot()
        metrics = ServiceMetrics(self.registry)
        api_metrics(self.registry)
        infos: list[ParameterInfo] = []
        kinds: dict[str, DriveInfo] = {}
        self.lines: dict[str, LineMetrics] = {}
        for n in range(lines):
            line = f"line{n}"
            names = [f"l{n}d{d}" for d in range(drives)]
            self.lines[line] = metrics.for_line(line, dict.fromkeys(names, FC))
            for i, drive in enumerate(names):
                kinds[drive] = DriveInfo(line, Profile.FC if i % 2 else Profile.PROFIDRIVE)
                for p in range(parameters):
                    unit = ODD if p == 1 else "Hz"
                    infos.append(ParameterInfo(line, drive, f"16-{p:02d}", p % 2, 1600 + p,
                                               f"Parameter {p}", unit, "u16"))  # fmt: skip
        self.infos = infos
        collector = SnapshotCollector(self.snapshot, kinds, infos)
        self.registry.register(collector)
        # As build_runtime wires it: the collector is one of the lines' outputs and hears of
        # new readings (``landed``), or (not) only scraped.
        self.outputs = Outputs([collector] if landed else [])

    def info_text(self) -> str:
        text = generate_latest(self.registry).decode()
        start = text.index("# HELP pkwbus_parameter_info")
        return text[start : text.index("# HELP", start + 1)]

    def poll(self, t: float) -> None:
        """Every parameter read at ``t`` (values of every kind Prometheus prints)."""
        special = [0.0, -0.0, 1e-7, 12345678.9, -3.5, math.inf, -math.inf, math.nan, 1e22]
        for i, p in enumerate(self.infos):
            value: float | int | str = special[i % len(special)] + (t if i % 3 else 0)
            if i % 7 == 6:
                value = "text"  # a text value: in the API, not in the metrics
            key, reading = (p.drive, p.parameter, p.index), Reading(value, i, t)
            self.snapshot.readings[key] = reading
            self.lines[p.line].on_events([ValueLanded(key, reading)])
            self.outputs.on_events([ValueLanded(key, reading)])
        for i, p in enumerate(self.infos[::4]):
            word = None if i % 5 == 4 else (int(t) * 97 + i) & 0xFFFF
            # A main actual value of either sign, or none (a drive without a second PZD word).
            mav = None if i % 4 == 1 else (int(t) * 4099 + i * 0x5000) & 0xFFFF
            self.snapshot.drives[p.drive] = DriveState(i % 3 != 2, word, t, mav)
        for n, line in enumerate(self.lines):
            self.snapshot.lines[line] = n % 2 == 0

    def traffic(self) -> None:
        for n, line in enumerate(self.lines.values()):
            drive = f"l{n}d0"
            line.on_events([Exchanged(drive, ErrorKind.TIMEOUT, 0.02)])
            line.job_finished(drive, JobKind.READ, JobResult(Rejected(3, "x", "y")))
            line.job_finished(drive, JobKind.READ, JobResult(TimedOut("gone")))
            line.on_events([Overrun(drive)])
        self.lines["line0"].job_finished(
            "stranger", JobKind.WRITE, JobResult(Rejected(None, "", ""))
        )


def _text(plant: Plant) -> str:
    return asyncio.run(render(plant.registry)).decode()


def _samples(text: str) -> list[tuple[str, tuple[tuple[str, str], ...], str]]:
    """Every sample: name, labels, value (as text, so that NaN equals NaN)."""
    return [
        (s.name, tuple(sorted(s.labels.items())), repr(s.value))
        for family in text_string_to_metric_families(text)
        for s in family.samples
    ]


@pytest.mark.parametrize("created", [False, True])
@pytest.mark.parametrize("landed", [False, True])
def test_the_text_is_generate_latest_of_the_same_registry(
    landed: bool, created: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Sample by sample (names, labels, values) and byte for byte, after each change:
    a value, a timestamp, a drive's state, a counter, a new series; whether the lines
    were made when the values landed or at the scrape; with the ``_created`` samples of
    prometheus_client's counters and histograms (generate_latest renders those) or
    without, as the service runs (their text made from their values)."""
    monkeypatch.setattr(client_metrics, "_use_created", created)
    plant = Plant(landed=landed)
    for step in range(4):
        plant.poll(1_700_000_000.25 + step)
        if step >= 2:
            plant.traffic()
        text = _text(plant)
        expected = generate_latest(plant.registry).decode()
        assert _samples(text) == _samples(expected)
        assert text == expected
    assert 'unit="Motor \\"A\\" \\\\ 1\\nÜberlast"' in text
    # A value of the other sign of zero, a text after a number, a number after a text;
    # a drive whose status word stays while its main actual value and state change.
    info = plant.infos[0]
    key = (info.drive, info.parameter, info.index)
    drive = plant.snapshot.drives[info.drive]
    line = plant.lines[info.line]
    for t, value in enumerate([0.0, -0.0, 0.0, "text", 5.0, -0.0], start=1):
        reading = Reading(value, 0, 1_700_000_100.0 + t)
        plant.snapshot.readings[key] = reading
        line.on_events([ValueLanded(key, reading)])
        plant.snapshot.drives[info.drive] = DriveState(
            t % 2 == 0, drive.status_word, 1_700_000_100.0 + t, (drive.main_actual or 0) + t
        )
        assert _text(plant) == generate_latest(plant.registry).decode(), value


def test_unchanged_series_reuse_their_line_and_changed_ones_are_made_again() -> None:
    plant = Plant(lines=1, drives=1, parameters=1)
    plant.poll(100.0)
    first = _text(plant)
    assert _text(plant) == first
    plant.snapshot.readings[("l0d0", "16-00", 0)] = Reading(42.5, 425, 101.0)
    plant.lines["line0"].on_events([Overrun("l0d0")])
    second = _text(plant)
    assert (
        'pkwbus_parameter_value{drive="l0d0",index="0",line="line0",parameter="16-00"} 42.5\n'
        in second
    )
    assert 'pkwbus_poll_overruns_total{drive="l0d0",line="line0"} 0.0\n' in first
    assert 'pkwbus_poll_overruns_total{drive="l0d0",line="line0"} 1.0\n' in second
    assert second == generate_latest(plant.registry).decode()


def test_a_value_that_disappears_from_the_snapshot_disappears_from_the_text() -> None:
    plant = Plant(lines=1, drives=1, parameters=2)
    plant.poll(100.0)
    del plant.snapshot.readings[("l0d0", "16-01", 1)]
    text = _text(plant)
    assert 'parameter="16-01"' not in text.split("# HELP pkwbus_parameter_info")[0]
    assert text == generate_latest(plant.registry).decode()


@pytest.mark.parametrize("landed", [True, False])
def test_values_are_rendered_when_their_poll_lands_so_the_scrape_only_joins(
    landed: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    plant = Plant(lines=2, drives=5, parameters=6, landed=landed)
    plant.poll(1_700_000_000.5)
    formatted = 0

    def counting(value: float) -> str:
        nonlocal formatted
        formatted += 1
        return format_value(value)

    monkeypatch.setattr(devices, "format_value", counting)
    text = _text(plant)
    assert text == generate_latest(plant.registry).decode()
    drives_lines = 2 * len(plant.snapshot.drives)  # status word, main actual value
    if landed:
        assert formatted <= drives_lines  # no value or timestamp line made at the scrape
    else:  # a reading nobody reported is rendered at the scrape, the same text
        assert formatted > drives_lines


def test_promtool_accepts_the_text() -> None:
    if not shutil.which(PROMTOOL):
        print(f"promtool not found ({PROMTOOL}): deploy/check installs it")
        pytest.skip(f"promtool not found at {PROMTOOL}; deploy/check installs it")
    plant = Plant()
    plant.poll(1_700_000_000.5)
    plant.traffic()
    body = asyncio.run(render(plant.registry))
    result = subprocess.run(
        [PROMTOOL, "check", "metrics"], input=body, capture_output=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def test_the_scrape_returns_to_the_event_loop_once_its_time_is_up() -> None:
    """A large configuration is rendered in pieces: once TURN_EVERY seconds of rendering
    have passed, another task runs before the next piece; a render that takes less time
    takes no turn. A fake clock: each look at it is ``step`` seconds later."""
    plant = Plant(lines=2, drives=100, parameters=20)
    plant.poll(1_700_000_000.5)
    pieces = sum(1 for p in plant.registry.exposition() if p)

    async def scrape(step: float) -> tuple[int, bytes]:
        now, turns, done = 0.0, 0, False

        def clock() -> float:
            nonlocal now
            now += step
            return now

        async def other() -> None:
            nonlocal turns
            while not done:
                turns += 1
                await asyncio.sleep(0)

        task = asyncio.create_task(other())
        await asyncio.sleep(0)
        start = turns
        body = await render(plant.registry, clock=clock)
        done = True
        await task
        return turns - start, body

    turns, body = asyncio.run(scrape(exposition.TURN_EVERY))  # each piece takes it all
    assert turns >= pieces - 1, (turns, pieces)
    assert body == generate_latest(plant.registry)
    turns, body = asyncio.run(scrape(exposition.TURN_EVERY / (4 * pieces)))  # a quarter
    assert turns == 0
    assert body == generate_latest(plant.registry)


def test_the_content_type_is_the_text_format_0_0_4() -> None:
    assert exposition.CONTENT_TYPE == "text/plain; version=0.0.4; charset=utf-8"


@settings(deadline=None, max_examples=500)
@given(st.floats(allow_nan=True, allow_infinity=True) | st.integers(-(2**63), 2**63))
def test_values_are_printed_as_prometheus_client_prints_them(value: float) -> None:
    assert format_value(value) == floatToGoString(value)


def test_a_counter_family_is_made_again_only_after_one_of_its_series_changed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    plant = Plant(lines=2, drives=4, parameters=2)
    plant.poll(100.0)
    plant.traffic()
    first = _text(plant)
    made = 0
    line = exposition.Series.line

    def counting(self: exposition.Series) -> str:
        nonlocal made
        made += 1
        return line(self)

    monkeypatch.setattr(exposition.Series, "line", counting)
    assert _text(plant) == first
    assert made == 0, "no counter changed: every family's text was kept"
    plant.traffic()  # a timeout, faults, an overrun on each line
    text = _text(plant)
    assert made > 0 and text != first
    assert text == generate_latest(plant.registry).decode()
