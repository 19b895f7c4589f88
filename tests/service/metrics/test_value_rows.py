"""The values' and drives' lines kept between scrapes (metrics.rows): a scrape shows what
the snapshot holds at that moment, whatever was announced, and makes only what changed."""

from __future__ import annotations

import asyncio

import pytest
from prometheus_client import generate_latest

from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import DriveState, Snapshot
from pkwbus.protocol.pzd import Profile
from pkwbus.service.metrics import devices
from pkwbus.service.metrics.devices import DriveInfo, ParameterInfo, SnapshotCollector
from pkwbus.service.metrics.exposition import CHUNK, MetricsRegistry, render

DRIVES, PARAMETERS = 30, 20  # 600 values: more than one piece of CHUNK lines


class Values:
    def __init__(self) -> None:
        self.snapshot = Snapshot()
        self.registry = MetricsRegistry()
        drives = {f"d{n}": DriveInfo("line0", Profile.FC) for n in range(DRIVES)}
        self.infos = [
            ParameterInfo("line0", d, f"16-{p:02d}", 0, 1600 + p, f"P{p}", "Hz", "u16")
            for d in drives
            for p in range(PARAMETERS)
        ]
        self.collector = SnapshotCollector(self.snapshot, drives, self.infos)
        self.registry.register(self.collector)
        assert len(self.infos) > CHUNK

    def land(self, n: int, value: float | int | str, t: float, *, told: bool = True) -> None:
        info = self.infos[n]
        key, reading = (info.drive, info.parameter, 0), Reading(value, 0, t)
        self.snapshot.readings[key] = reading
        if told:
            self.collector.landed(key, reading)

    def text(self) -> str:
        text = asyncio.run(render(self.registry)).decode()
        assert text == generate_latest(self.registry).decode()
        return text


def _line(n: int, value: str) -> str:
    drive, parameter = f"d{n // PARAMETERS}", f"16-{n % PARAMETERS:02d}"
    labels = f'drive="{drive}",index="0",line="line0",parameter="{parameter}"'
    return f"pkwbus_parameter_value{{{labels}}} {value}\n"


@pytest.fixture
def values() -> Values:
    v = Values()
    for n in range(len(v.infos)):
        v.land(n, n, 100.0)
    v.text()
    return v


def test_a_value_replaced_without_a_landing_is_shown_at_the_next_scrape(values: Values) -> None:
    for n in (3, CHUNK + 7):  # in the first piece and in a later one
        values.land(n, 4242.5, 101.0, told=False)
        assert _line(n, "4242.5") in values.text()
        values.land(n, 0.0, 102.0)
        values.land(n, -0.0, 102.0, told=False)  # equal to 0.0, printed otherwise
        assert _line(n, "-0.0") in values.text()


def test_a_landing_the_snapshot_does_not_hold_is_not_shown(values: Values) -> None:
    info = values.infos[CHUNK + 1]
    key = (info.drive, info.parameter, 0)
    values.land(CHUNK + 1, 7.0, 103.0)
    values.collector.landed(key, Reading(8.0, 0, 104.0))  # told, but not what it holds
    assert _line(CHUNK + 1, "7.0") in values.text()
    # A value no scrape has shown yet (a new key) likewise.
    new = ("stranger", "1-20", 0)
    values.collector.landed(new, Reading(8.0, 0, 104.0))
    values.snapshot.readings[new] = Reading(9.0, 0, 104.0)
    assert 'pkwbus_parameter_value{drive="stranger",index="0",line="",parameter="1-20"} 9.0\n' in (
        values.text()
    )


def test_a_scrape_joins_what_landed_and_makes_nothing(
    values: Values, monkeypatch: pytest.MonkeyPatch
) -> None:
    formatted = 0

    def counting(value: float) -> str:
        nonlocal formatted
        formatted += 1
        return f"{value!r}"

    monkeypatch.setattr(devices, "format_value", counting)
    values.land(CHUNK + 2, 99.5, 105.0)
    assert formatted == 2  # the value and its timestamp, when it landed
    assert _line(CHUNK + 2, "99.5") in values.text()
    assert formatted == 2  # and nothing at the scrape
    values.text()
    assert formatted == 2


def test_values_that_come_and_go_keep_the_snapshot_s_order(values: Values) -> None:
    first = values.infos[0]
    del values.snapshot.readings[(first.drive, first.parameter, 0)]
    values.snapshot.readings[("stranger", "1-20", 0)] = Reading(5.0, 5, 106.0)
    values.land(1, "a text", 106.0)  # a text: no line
    text = values.text()
    shown = text.split("# HELP")[1]  # the values' family
    assert 'drive="stranger"' in shown
    assert (
        _line(0, "0.0") not in shown
        and '"d0",index="0",line="line0",parameter="16-01"' not in shown
    )
    values.land(0, 1.0, 107.0)  # back, at the end of the snapshot's order
    values.text()


def test_a_drive_moved_to_another_line_is_shown_with_it(values: Values) -> None:
    values.collector.forget_drive("d1")
    infos = [
        ParameterInfo("line9", "d1", i.parameter, 0, i.pnu, i.name, i.unit, i.type)
        for i in values.infos
        if i.drive == "d1"
    ]
    values.collector.add_drive("d1", DriveInfo("line9", Profile.FC), infos)
    text = values.text()  # the snapshot still holds the same readings of d1
    assert 'pkwbus_parameter_value{drive="d1",index="0",line="line9",parameter="16-00"}' in text


def test_each_change_of_a_drive_s_state_is_shown(values: Values) -> None:
    drives = values.snapshot.drives
    steps = [
        DriveState(True, 0x0F07, 1.0, 0x2000),
        DriveState(True, 0x0F07, 2.0, 0x2000),  # a new object, the same lines
        DriveState(False, 0x0F07, 3.0, 0x2000),  # down: its up line alone changes
        DriveState(False, 0x0F07, 4.0, 0x2100),  # another main actual value
        DriveState(True, 0x0B07, 5.0, 0x2100),  # another word: its bits
        DriveState(True, 0x0B07, 6.0, None),  # a word without a main actual value
        DriveState(True, None, 7.0, None),
    ]
    for state in steps:
        for n in range(DRIVES):
            drives[f"d{n}"] = state
        text = values.text()
        assert f'pkwbus_drive_up{{drive="d29",line="line0"}} {float(state.up)}\n' in text


class Listed(dict[tuple[str, str, int], Reading]):
    """The snapshot's readings, counting how often their keys are listed."""

    listed = 0

    def __iter__(self):  # type: ignore[no-untyped-def]
        self.listed += 1
        return super().__iter__()


def _render(values: Values) -> str:
    return asyncio.run(render(values.registry)).decode()


def test_a_scrape_after_told_landings_does_not_list_the_keys(values: Values) -> None:
    readings = values.snapshot.readings = Listed(values.snapshot.readings)
    values.land(5, 1.5, 200.0)
    values.land(CHUNK + 5, 2.5, 200.0)
    text = _render(values)
    assert readings.listed == 0  # every place holds what its row was made of
    assert _line(5, "1.5") in text and _line(CHUNK + 5, "2.5") in text
    values.land(7, 3.5, 201.0, told=False)  # not told: the keys are compared, then shown
    text = _render(values)
    assert readings.listed == 1 and _line(7, "3.5") in text
    assert text == values.text()
    values.collector.landed(("gone", "1-20", 0), Reading(1.0, 1, 202.0))  # not held
    assert 'drive="gone"' not in _render(values) and readings.listed == 2
    values.land(9, 4.5, 203.0)
    assert _line(9, "4.5") in _render(values) and readings.listed == 2  # not listed again


def test_keys_that_move_or_swap_untold_are_shown_in_the_snapshot_s_order(values: Values) -> None:
    readings = values.snapshot.readings
    second = values.infos[1]
    key = (second.drive, second.parameter, 0)
    readings[key] = readings.pop(key)  # the same object, now at the end
    assert _line(1, "1.0") in values.text()  # Values.text: the order of generate_latest
    held = readings.pop(next(reversed(readings)))  # the last: key 1, as it moved
    readings[("stranger", "1-20", 0)] = held  # the same size, the same object at each place
    text = values.text()  # Values.text: generate_latest's text, not the row of key 1
    assert 'drive="stranger"' in text and _line(1, "1.0") not in text


def test_a_main_actual_value_that_moved_leaves_the_other_pieces_of_the_drives(
    values: Values,
) -> None:
    drives, rows = values.snapshot.drives, values.collector._drive_rows
    for n in range(DRIVES):
        drives[f"d{n}"] = DriveState(True, 0x0F07, 1.0, 0x2000)
    values.text()
    before = rows.sync(drives)
    for n in range(DRIVES):
        drives[f"d{n}"] = DriveState(True, 0x0F07, 2.0, 0x2000 + 64 * n)
    text = values.text()
    after = rows.sync(drives)
    ups, words, bits, mavs = (
        all(a is b for a, b in zip(old, new, strict=True))
        for old, new in zip(before, after, strict=True)
    )
    assert ups and words and bits and not mavs  # only the main actual values joined again
    percent = (0x2000 + 64 * 29) / 0x4000 * 100  # 0x4000: 100 % of nominal
    assert f'pkwbus_drive_main_actual_percent{{drive="d29",line="line0"}} {percent}\n' in text
