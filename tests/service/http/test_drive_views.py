"""GET /api/v1/drives at plant scale: it costs what it returns (each reading it shows looked
at once, nothing else), it answers one line, one drive, or only the drives changed since
an earlier answer's token, and an overview of one short row per drive."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pkwbus.master.reading import Reading
from pkwbus.master.snapshot import ReadingKey
from pkwbus.service.http.views.drives import TOKEN_HEADER, drive_view
from tests.service.http.conftest import AUTH, fc_drives, service

# Polled once at the start, then not for a minute: the drives keep still while a test looks.
QUIET = [("16-13", "60s"), ("16-14", "60s"), ("1-20", "60s")]


class CountedReadings(dict[ReadingKey, Reading]):
    """The snapshot's readings, counting every reading a reader looks at."""

    looked = 0

    def __getitem__(self, key: ReadingKey) -> Reading:
        self.looked += 1
        return super().__getitem__(key)

    def get(self, key: ReadingKey, default: Any = None) -> Any:
        self.looked += 1
        return super().get(key, default)

    def __contains__(self, key: object) -> bool:
        self.looked += 1
        return super().__contains__(key)

    def __iter__(self) -> Any:
        for key in super().__iter__():
            self.looked += 1
            yield key

    def items(self) -> Any:
        for item in super().items():
            self.looked += 1
            yield item

    def values(self) -> Any:
        for value in super().values():
            self.looked += 1
            yield value

    def keys(self) -> Any:
        return list(iter(self))


def values_in(answer: list[dict[str, Any]]) -> int:
    return sum(len(d["values"]) for d in answer)


async def test_the_drives_view_looks_at_each_reading_it_returns_once(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        snapshot = svc.runtime.snapshot
        held = {d: sum(1 for k in snapshot.readings if k[0] == d) for d in svc.runtime.drives}
        assert held["fan2"] > len(QUIET)  # the configured polls and the catalog's own
        counted = CountedReadings(snapshot.readings)
        snapshot.readings = counted
        one = (await svc.client.get("/api/v1/drives", params={"drive": "fan2"})).json()
        assert [d["name"] for d in one] == ["fan2"]
        assert values_in(one) == held["fan2"], "every polled value of the drive is shown"
        assert counted.looked == held["fan2"], "only that drive's readings, each once"
        counted.looked = 0
        every = (await svc.client.get("/api/v1/drives")).json()
        assert values_in(every) == sum(held.values())
        # fan2's view is kept from the answer before (nothing of it changed): the other two
        # drives' readings are looked at, once each.
        assert counted.looked == held["fan1"] + held["fan3"]


async def test_the_same_parameter_order_on_every_drive_and_the_poll_interval(
    tmp_path: Path,
) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        answer = (await svc.client.get("/api/v1/drives")).json()
        orders = {tuple(v["parameter"] for v in d["values"]) for d in answer}
        (order,) = orders
        assert order[:3] == tuple(p for p, _ in QUIET), "the configured polls first, in order"
        entry = svc.runtime.drives["fan1"]
        every = {(p.parameter, p.index): p.every for p in entry.polls}
        for d in answer:
            assert all(v["interval"] == every[(v["parameter"], v["index"])] for v in d["values"])
        assert {v["interval"] for v in answer[0]["values"][:3]} == {60.0}


async def test_only_the_drives_changed_since_the_token(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        first = await svc.client.get("/api/v1/drives")
        token = first.headers[TOKEN_HEADER]
        assert len(first.json()) == 3
        still = await svc.client.get("/api/v1/drives", params={"changed_since": token})
        assert still.status_code == 200 and still.json() == []
        token = still.headers[TOKEN_HEADER]
        url = "/api/v1/drives/fan2/maintenance"
        r = await svc.client.put(url, json={"on": True, "reason": "belt"}, headers=AUTH)
        assert r.status_code == 200, r.text
        changed = await svc.client.get("/api/v1/drives", params={"changed_since": token})
        assert [d["name"] for d in changed.json()] == ["fan2"]
        assert changed.json()[0]["maintenance"]["reason"] == "belt"
        assert changed.headers[TOKEN_HEADER] != token
        # A token of another run (or none the service gave) is answered with every drive.
        for other in ("0.0", "nonsense", f"{token}9"):
            again = await svc.client.get("/api/v1/drives", params={"changed_since": other})
            assert [d["name"] for d in again.json()] == ["fan1", "fan2", "fan3"]


async def test_one_line_one_drive_and_what_is_not_there(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        on_line = (await svc.client.get("/api/v1/drives", params={"line": "line_fc"})).json()
        assert [d["name"] for d in on_line] == ["fan1", "fan2", "fan3"]
        for query, kind in (({"line": "nowhere"}, "unknown_line"),
                            ({"drive": "nobody"}, "unknown_drive")):  # fmt: skip
            r = await svc.client.get("/api/v1/drives", params=query)
            assert r.status_code == 404 and r.json()["error"]["kind"] == kind
        r = await svc.client.get("/api/v1/drives", params={"view": "everything"})
        assert r.status_code == 422


async def test_the_overview_is_one_short_row_per_drive(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        url = "/api/v1/drives/fan3/maintenance"
        r = await svc.client.put(url, json={"on": True, "reason": "belt"}, headers=AUTH)
        assert r.status_code == 200, r.text
        rows = (await svc.client.get("/api/v1/drives", params={"view": "overview"})).json()
        full = {d["name"]: d for d in (await svc.client.get("/api/v1/drives")).json()}
        assert [r["name"] for r in rows] == ["fan1", "fan2", "fan3"]
        for row in rows:
            view = full[row["name"]]
            assert (row["line"], row["address"]) == (view["line"], view["address"])
            assert row["faults"] == view["faults"]
            newest = max(v["timestamp"] for v in view["values"])
            assert row["updated"] == newest and row["age"] >= 0
            assert "values" not in row
        assert [r["state"] for r in rows] == ["up", "up", "maintenance"]


async def test_one_drives_trends(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        every = (await svc.client.get("/api/v1/trends")).json()
        one = await svc.client.get("/api/v1/trends", params={"drive": "fan2"})
        assert one.status_code == 200 and one.json() == {"fan2": every["fan2"]}
        assert every["fan2"], "its values have points"
        r = await svc.client.get("/api/v1/trends", params={"drive": "nobody"})
        assert r.status_code == 404 and r.json()["error"]["kind"] == "unknown_drive"


async def test_the_kept_json_is_the_drives_view(tmp_path: Path) -> None:
    """What the answer joins from its kept pieces says what the drive's view says."""
    async with service(tmp_path, fc=fc_drives(polls=QUIET)) as svc:
        for _ in range(2):  # made, then (partly) kept
            answer = (await svc.client.get("/api/v1/drives")).json()
            for got in answer:
                view = drive_view(svc.runtime, got["name"]).model_dump(mode="json")
                assert got == view
