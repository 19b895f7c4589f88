"""GET /api/v1/lines and the counts in /api/v1/drives: what the status page shows of a line."""

from __future__ import annotations

import asyncio
from pathlib import Path

from tests.service.http.conftest import fc_drives, service


async def test_lines_say_how_busy_they_were_since_the_last_look(tmp_path: Path) -> None:
    drives = fc_drives()
    async with service(tmp_path, fc=drives) as svc:
        refused = await svc.client.get(f"/api/v1/drives/{drives[0]['name']}/parameters/19-99")
        assert refused.status_code == 409  # the drive has no 19-99: a fault it counts
        first = (await svc.client.get("/api/v1/lines")).json()
        assert [line["utilisation"] for line in first] == [None] * len(first)
        await asyncio.sleep(0.5)
        lines = (await svc.client.get("/api/v1/lines")).json()
        (line,) = lines
        assert line["open"] and line["drives"] == len(drives) == line["drives_up"]
        assert line["busy_seconds"] > first[0]["busy_seconds"]
        assert 0 < line["utilisation"] <= 1
        views = {d["name"]: d for d in (await svc.client.get("/api/v1/drives")).json()}
        assert views[drives[0]["name"]]["faults"] > 0
        assert all(v["faults"] == 0 for name, v in views.items() if name != drives[0]["name"])
        assert all(v["telegram_errors"] == 0 for v in views.values())
