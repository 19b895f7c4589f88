"""The drives' settings through the running service and simulated drives on TCP: a change
made at the keypad is caught within two sweeps (shown, exported, logged once as an event);
a write pkwbus makes through the API moves the baseline and is never flagged; a backup of
drive A restored onto factory-set drive B leaves B equal to A at the simulator, one audit
row and an EEPROM write per setting; a dry run writes nothing; a baseline outlives a
restart."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from prometheus_client import generate_latest

from pkwbus.protocol.pkw.dialects import Command
from pkwbus.service.history.settings import KIND
from pkwbus.sim import Simulator
from tests.master.conftest import until as until_within
from tests.service.http.conftest import AUTH, Service, fc_drives, service

EVERY = "1s"  # a sweep of the 14 settings of the danfoss-fc catalog a second


async def until(check: Callable[[], bool], timeout: float = 40.0) -> None:
    await until_within(check, timeout)


def watcher(svc: Service) -> Any:
    assert svc.runtime.settings is not None
    return svc.runtime.settings


def completed(svc: Service, drive: str) -> int:
    return int(watcher(svc).swept[drive].completed)


def swept(svc: Service, drive: str, sweeps: int = 1) -> Callable[[], bool]:
    return lambda: completed(svc, drive) >= sweeps


def changed_series(svc: Service) -> list[str]:
    text = generate_latest(svc.runtime.registry).decode()
    return [x for x in text.splitlines() if x.startswith("pkwbus_drive_setting_changed{")]


async def settings_of(svc: Service, drive: str) -> dict[str, dict[str, Any]]:
    r = await svc.client.get(f"/api/v1/drives/{drive}/settings")
    assert r.status_code == 200, r.text
    return {p["parameter"]: p for p in r.json()["parameters"]}


def stop(sim: Simulator, address: int) -> None:
    """The motor stopped (ramped down at once)."""
    sim.drives[address].model.running = False
    sim.drives[address].model.frequency = 0.0


def stored(sim: Simulator, address: int, pnu: int) -> int:
    return sim.drives[address].value(pnu)


async def test_a_keypad_change_is_caught_within_two_sweeps_and_told_once(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:2], settings=f"{{every: {EVERY}}}") as svc:
        await until(swept(svc, "fan1"))
        before = await settings_of(svc, "fan1")
        assert not any(p["changed"] for p in before.values())
        old = stored(svc.sim, 1, 341)
        svc.sim.keypad(1, 341, old + 150)  # 3-41 Ramp 1 Ramp Up Time, at the drive
        at = completed(svc, "fan1")
        await until(lambda: any('parameter="3-41"' in s for s in changed_series(svc)))
        assert completed(svc, "fan1") - at <= 2, "caught within two sweeps"
        (series,) = changed_series(svc)
        assert 'drive="fan1"' in series and 'index="0"' in series
        now = await settings_of(svc, "fan1")
        ramp = now["3-41"]
        assert ramp["changed"] is True and ramp["changed_seen"] is not None
        assert ramp["raw"] == old + 150 and ramp["baseline"] == before["3-41"]["value"]
        assert ramp["factory"] == before["3-41"]["factory"], "FC element 20 stays the factory's"
        # One event while the change lasts, however many sweeps see it.
        await until(swept(svc, "fan1", completed(svc, "fan1") + 2))
        r = await svc.client.get("/api/v1/events", params={"drive": "fan1"})
        events = [e for e in r.json()["events"] if e["kind"] == KIND]
        assert [(e["code"], e["value"]) for e in events] == [("3-41", old + 150)]
        assert events[0]["text"] == ramp["name"]
        # Back at the drive: no longer flagged; accepted as baseline: neither.
        svc.sim.keypad(1, 341, old)
        await until(lambda: changed_series(svc) == [])
        assert (await settings_of(svc, "fan1"))["3-41"]["changed"] is False


async def test_an_audited_write_moves_the_baseline_and_is_never_flagged(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:1], settings=f"{{every: {EVERY}}}") as svc:
        await until(swept(svc, "fan1"))
        baseline = (await settings_of(svc, "fan1"))["3-41"]["baseline"]
        r = await svc.put("fan1", "3-41", {"value": baseline + 2.5})
        assert r.status_code == 200, r.text
        at = completed(svc, "fan1")
        await until(swept(svc, "fan1", at + 2))
        ramp = (await settings_of(svc, "fan1"))["3-41"]
        assert ramp["value"] == ramp["baseline"] == baseline + 2.5
        assert ramp["baseline_by"] == "write" and ramp["changed"] is False
        assert changed_series(svc) == []
        r = await svc.client.get("/api/v1/events", params={"drive": "fan1"})
        assert [e for e in r.json()["events"] if e["kind"] == KIND] == []


async def test_accepting_the_present_values_as_baseline_is_audited(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:1], settings=f"{{every: {EVERY}}}") as svc:
        await until(swept(svc, "fan1"))
        svc.sim.keypad(1, 342, stored(svc.sim, 1, 342) + 100)
        await until(lambda: changed_series(svc) != [])
        url = "/api/v1/drives/fan1/settings/baseline"
        assert (await svc.client.put(url)).status_code == 401
        assert changed_series(svc) != [], "nothing accepted without the token"
        r = await svc.client.put(url, headers=AUTH)
        assert r.status_code == 200 and r.json()["accepted"] >= 1
        assert changed_series(svc) == []
        assert (await settings_of(svc, "fan1"))["3-42"]["baseline_by"] == "accepted"
        assert svc.audit is not None
        rows = [(row.parameter, row.outcome) for row in svc.audit.latest(5)]
        assert ("settings/baseline", "ok") in rows


async def test_a_backup_restored_onto_a_factory_drive_makes_it_equal(tmp_path: Path) -> None:
    drives = fc_drives()[:2]
    async with service(tmp_path, fc=drives, settings=f"{{every: {EVERY}}}") as svc:
        sim = svc.sim
        stop(sim, 1)  # motor data change only with the motor stopped
        changes = {341: 1234, 342: 777, 414: stored(sim, 1, 414) - 50, 120: 1100}
        for pnu, raw in changes.items():
            sim.keypad(1, pnu, raw)
        at = completed(svc, "fan1")
        await until(swept(svc, "fan1", at + 2))  # a whole sweep after the changes
        r = await svc.client.get("/api/v1/drives/fan1/backup")
        assert r.status_code == 200, r.text
        backup = r.json()
        held = {s["parameter"]: s["raw"] for s in backup["settings"]}
        assert {held["3-41"], held["3-42"], held["4-14"], held["1-20"]} == set(changes.values())
        yaml_text = (await svc.client.get("/api/v1/drives/fan1/backup?format=yaml")).text
        assert "pkwbus_backup: 1" in yaml_text and "3-41" in yaml_text
        await until(swept(svc, "fan2"))
        factory = {pnu: stored(sim, 2, pnu) for pnu in changes}
        url = "/api/v1/drives/fan2/restore"
        # A dry run plans every difference and writes nothing.
        r = await svc.client.post(url, json={"backup": backup, "dry_run": True}, headers=AUTH)
        assert r.status_code == 200, r.text
        planned = {p["parameter"] for p in r.json()["plan"]}
        assert {"3-41", "3-42", "4-14", "1-20"} <= planned
        assert {pnu: stored(sim, 2, pnu) for pnu in changes} == factory
        assert svc.audit_writer.writes(address=2) == []
        # With the motor running, the motor data are refused as the drive says, the rest go.
        r = await svc.client.post(url, json={"backup": backup}, headers=AUTH)
        assert r.status_code == 200, r.text
        results = {x["parameter"]: x for x in r.json()["results"]}
        assert results["1-20"]["outcome"] == "rejected" and results["1-20"]["when_stopped"]
        assert results["3-41"]["outcome"] == "ok"
        stop(sim, 2)
        r = await svc.client.post(url, json={"backup": backup}, headers=AUTH)
        results = {x["parameter"]: x for x in r.json()["results"]}
        assert set(results) == {"1-20"}, "only what still differs is written again"
        assert results["1-20"]["outcome"] == "ok"
        for pnu, raw in changes.items():
            assert stored(sim, 2, pnu) == raw, pnu
            assert sim.drives[2].eeprom[(pnu, 0)] == raw, "stored in EEPROM"
        writes = svc.audit_writer.writes(address=2)
        eeprom = {Command.WRITE_WORD_EEPROM, Command.WRITE_DWORD_EEPROM}
        assert writes and all(w.command in eeprom for w in writes), "RAM and EEPROM writes"
        assert svc.audit is not None
        rows = [row for row in svc.audit.latest(50) if row.drive == "fan2"]
        sent = [row for row in rows if row.outcome in ("ok", "rejected")]
        # One audit row per write sent: a write repeated until its answer came (a loaded
        # machine) is one write, one row.
        written = {(f"{w.pnu // 100}-{w.pnu % 100:02d}", w.value) for w in writes}
        assert {(row.parameter, row.raw_value) for row in sent} == written
        assert len(sent) <= len(writes)
        assert sum(1 for row in rows if row.outcome == "dry_run") == len(planned)
        # Restored by pkwbus: B's new values are its baseline, nothing flagged.
        await until(swept(svc, "fan2", completed(svc, "fan2") + 1))
        assert not any('drive="fan2"' in s for s in changed_series(svc))


async def test_a_backup_of_another_drive_type_is_skipped_unless_forced(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:1], settings=f"{{every: {EVERY}}}") as svc:
        await until(swept(svc, "fan1"))
        backup = (await svc.client.get("/api/v1/drives/fan1/backup")).json()
        backup["identity"] = "fc:FC-302P7K5|05.11"
        backup["settings"] = [s | {"raw": None, "value": 99.0} for s in backup["settings"]
                              if s["parameter"] == "3-41"]  # fmt: skip
        url = "/api/v1/drives/fan1/restore"
        body: dict[str, Any] = {"backup": backup, "dry_run": True}
        r = await svc.client.post(url, json=body, headers=AUTH)
        assert r.json()["plan"] == [] and "another drive type" in r.json()["skipped"][0]["why"]
        r = await svc.client.post(url, json=body | {"force": True}, headers=AUTH)
        assert [p["to"] for p in r.json()["plan"]] == [99.0]
        r = await svc.client.post(url, json={"backup": {"drive": 7}}, headers=AUTH)
        assert r.status_code == 422 and r.json()["error"]["kind"] == "invalid_backup"


async def test_a_change_flagged_before_a_restart_is_still_flagged_and_not_told_again(
    tmp_path: Path,
) -> None:
    drives: dict[str, Simulator] = {}  # the same simulated drives across the restart
    for run in range(2):
        async with service(tmp_path, fc=fc_drives()[:1], settings=f"{{every: {EVERY}}}",
                           keep=drives) as svc:  # fmt: skip
            if run == 0:
                await until(swept(svc, "fan1"))
                svc.sim.keypad(1, 341, stored(svc.sim, 1, 341) + 300)
                await until(lambda: changed_series(svc) != [])
                continue
            assert any('parameter="3-41"' in s for s in changed_series(svc)), "from the start"
            await until(swept(svc, "fan1", 2))
            assert any('parameter="3-41"' in s for s in changed_series(svc))
            r = await svc.client.get("/api/v1/events", params={"drive": "fan1"})
            assert len([e for e in r.json()["events"] if e["kind"] == KIND]) == 1


async def test_a_drive_identified_as_another_drive_starts_a_new_baseline(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives()[:1], settings=f"{{every: {EVERY}}}") as svc:
        await until(swept(svc, "fan1"))
        old = stored(svc.sim, 1, 341)
        svc.sim.keypad(1, 341, old + 100)
        await until(lambda: changed_series(svc) != [])
        first = watcher(svc).swept["fan1"].identity
        # The drive is replaced by another model: away, then back with another 15-40.
        svc.sim.kill(1)
        await until(lambda: not svc.runtime.snapshot.drives["fan1"].up)
        svc.sim.drives[1].params.texts[1540] = b"FC-302"
        svc.sim.revive(1)
        await until(lambda: watcher(svc).swept["fan1"].identity not in (None, first))
        assert changed_series(svc) == [], "the old drive's change is not the new one's"
        await until(swept(svc, "fan1", completed(svc, "fan1") + 2))  # a whole sweep after
        ramp = (await settings_of(svc, "fan1"))["3-41"]
        assert ramp["baseline"] == ramp["value"] and ramp["baseline_by"] == "sweep"
        assert changed_series(svc) == []
        r = await svc.client.get("/api/v1/events", params={"drive": "fan1"})
        codes = [e["code"] for e in r.json()["events"] if e["kind"] == KIND]
        assert codes == ["baseline", "3-41"], "the new baseline is told, newest first"
