"""The counters the drives keep of their own life, polled by default (``counters: auto``):
exported as parameter values and shown in the drive's view, with the types the drives
described; they advance as the drive's do."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pkwbus.catalog import load_catalog
from pkwbus.service.http.views import drives as drives_module
from pkwbus.service.http.views import readable as readable_module
from pkwbus.service.http.views.drives import _polled, _reading_fields
from pkwbus.service.http.views.readable import duration, time_unit
from tests.service.http.conftest import USS_DRIVES, fc_drives, service


def values(drive: dict[str, Any]) -> dict[tuple[str, int], dict[str, Any]]:
    return {(v["parameter"], v.get("index") or 0): v for v in drive["values"]}


async def test_the_drives_counters_are_polled_by_default_and_shown(tmp_path: Path) -> None:
    fc = fc_drives(polls=[("16-13", "50ms")])[:1]
    async with service(tmp_path, fc=fc, uss=USS_DRIVES) as svc:
        drives = {d["name"]: d for d in (await svc.client.get("/api/v1/drives")).json()}
        fan, pump = values(drives["fan1"]), values(drives["pump1"])
        for name in ("15-00", "15-01", "15-02", "15-03", "15-04", "15-05"):
            assert (name, 0) in fan, f"{name} in the drive's view"
        # As the drive counts: 15-03 Power Up's is the simulated drive's power-ups.
        sim_fan = svc.sims["fc"].drives[1]
        assert fan["15-03", 0]["value"] == sim_fan.model.power_ups
        for index in (0, 1, 2):
            assert ("r0039", index) in pump
        assert ("r2114", 0) in pump and ("r2114", 1) in pump
        # r2114 as the drive counts its runtime: days x 86,400,000 + ms, never ahead of it.
        shown = pump["r2114", 1]["value"] * 86_400_000 + pump["r2114", 0]["value"]
        assert 0 < shown <= svc.sims["uss"].drives[1].model.runtime_ms
        # Read out as durations (the catalog's units: 15-00 raw hours in s, r2114 [0] ms and
        # [1] days), the values and units as the drives give them.
        hours, ms, days = fan["15-00", 0], pump["r2114", 0], pump["r2114", 1]
        assert (hours["unit"], hours["value"] % 3600) == ("s", 0)
        assert hours["shown"] == f"{hours['value'] // 3600:,} h"
        assert days["shown"] == f"{days['value']:,} d" and days["unit"] == ""
        seconds = ms["value"] // 1000
        clock = f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"
        assert ms["shown"] == clock and ms["unit"] == ""
        metrics = (await svc.client.get("/metrics")).text
        assert 'parameter="r2114"' in metrics and 'parameter="15-03"' in metrics


def test_the_catalogs_name_the_counters_they_mark() -> None:
    for catalog in ("danfoss-fc", "siemens-g120"):
        marked = [s for s in load_catalog(catalog).parameters.values() if s.counter]
        assert marked and all(s.name for s in marked)
        # What a counter's entry could not source is said (then only the drive types it).
        assert all(s.verified or "recalled" in s.note for s in marked)


async def test_a_durations_value_is_worked_out_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A counter of time is read out as a duration once per value made (the drives' view
    makes about 1,000 values an answer at plant scale), and says what it said before."""
    fc = fc_drives(polls=[("16-13", "50ms")])[:1]
    async with service(tmp_path, fc=fc, uss=USS_DRIVES) as svc:
        before = {d["name"]: values(d) for d in (await svc.client.get("/api/v1/drives")).json()}
        runtime = svc.runtime
        items = [x for name in runtime.drives for x in _polled(runtime, runtime.drives[name])]
        durations = [x for x in items if time_unit(x[2]) and not isinstance(x[1].value, str)]
        assert durations, "the drives' counters are polled"
        calls = 0

        def counted(*args: Any) -> str | None:
            nonlocal calls
            calls += 1
            return duration(*args)

        monkeypatch.setattr(drives_module, "duration", counted)
        monkeypatch.setattr(readable_module, "duration", counted)
        for poll, reading, fmt, source, name in items:
            fields = _reading_fields(runtime, poll, reading, fmt, source, name)
            was = before[name][poll.parameter, poll.index]
            if was["value"] == fields["value"]:
                assert (fields["shown"], fields["shown_unit"]) == (was["shown"], was["shown_unit"])
        assert calls == len(durations)
