"""``GET /api/v1/drives?view=overview``: each row names the drive's bus as its view does,
a PROFIBUS DP slave's state in the live list as its view's ``dp.state``, and how many of
its settings differ from their baseline as its settings view counts them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tests.master.conftest import until
from tests.service.assembly.test_dp_service import dp_service
from tests.service.http.conftest import fc_drives, service


async def rows_of(client: Any) -> dict[str, dict[str, Any]]:
    r = await client.get("/api/v1/drives", params={"view": "overview"})
    assert r.status_code == 200, r.text
    return {row["name"]: row for row in r.json()}


async def views_of(client: Any) -> dict[str, dict[str, Any]]:
    r = await client.get("/api/v1/drives")
    assert r.status_code == 200, r.text
    return {view["name"]: view for view in r.json()}


async def changed_settings(client: Any, drive: str) -> int:
    r = await client.get(f"/api/v1/drives/{drive}/settings")
    assert r.status_code == 200, r.text
    return sum(1 for p in r.json()["parameters"] if p["changed"])


async def test_fc_rows_name_their_bus_and_no_dp_state_or_settings(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:2]) as svc:
        rows = await rows_of(svc.client)
        views = await views_of(svc.client)
        assert set(rows) == set(views) == {"fan1", "fan2"}
        for name, row in rows.items():
            assert row["protocol"] == views[name]["protocol"] == "fc"
            assert row["dp_state"] is None and views[name]["dp"] is None
            # Not swept (no settings configured): no count, not a zero.
            assert row["settings_changed"] is None and views[name]["settings"] is False


async def test_a_dp_slave_row_shows_its_state_in_the_live_list(tmp_path: Path) -> None:
    async with dp_service(tmp_path) as svc:
        rows = await rows_of(svc.client)
        views = await views_of(svc.client)
        for name, row in rows.items():
            assert row["protocol"] == views[name]["protocol"] == "profibus"
            assert row["dp_state"] == views[name]["dp"]["state"] == "data_exchange"
        svc.sim.kill(10)  # "fan" is gone from the bus: out of data exchange

        async def fan_left() -> bool:
            return (await rows_of(svc.client))["fan"]["dp_state"] != "data_exchange"

        await until(fan_left, 40, step=0.1)
        rows, views = await rows_of(svc.client), await views_of(svc.client)
        assert rows["fan"]["dp_state"] == views["fan"]["dp"]["state"] != "data_exchange"
        assert rows["pump"]["dp_state"] == "data_exchange"


async def test_the_row_counts_the_settings_that_differ_from_their_baseline(
    tmp_path: Path,
) -> None:
    async with service(tmp_path, fc=fc_drives()[:2], settings="{every: 1s}") as svc:
        watcher: Any = svc.runtime.settings
        await until(lambda: all(watcher.swept[d].completed >= 1 for d in ("fan1", "fan2")), 40)
        rows = await rows_of(svc.client)
        assert rows["fan1"]["settings_changed"] == 0 == await changed_settings(svc.client, "fan1")
        # Two settings changed at fan1's keypad, found by its next sweeps.
        svc.sim.keypad(1, 341, svc.sim.drives[1].value(341) + 150)
        svc.sim.keypad(1, 342, svc.sim.drives[1].value(342) + 150)

        async def both_found() -> bool:
            return await changed_settings(svc.client, "fan1") == 2

        await until(both_found, 40, step=0.1)

        async def counted() -> bool:  # the read model has it with the line's next batch
            return (await rows_of(svc.client))["fan1"]["settings_changed"] == 2

        await until(counted, 40, step=0.1)
        assert rows["fan2"]["settings_changed"] == 0 == await changed_settings(svc.client, "fan2")
