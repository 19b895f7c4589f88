"""What the drive and the line make of a write: 409 with the drive's fault, 504 without answer."""

from __future__ import annotations

import asyncio
from pathlib import Path

from pkwbus.protocol.pkw.dialects import Command
from pkwbus.sim import SimTiming, Simulator
from tests.master.conftest import until
from tests.service.http.conftest import POLLED_WRITABLES, STEADY, fc_drives, service


async def test_not_while_running_is_409_with_fault_17(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=POLLED_WRITABLES)) as svc:
        drive = svc.sim.drives[1]
        assert drive.running
        before = drive.value(120)
        r = await svc.put("fan1", "1-20", {"value": 7500})  # 7.5 kW, in W
        assert r.status_code == 409, r.text
        error = r.json()["error"]
        assert error["kind"] == "rejected"
        assert error["fault"] == 17
        assert error["text"]
        assert drive.value(120) == before
        assert len(svc.audit_writer.writes(1, 120)) == 1  # sent once: a rejection is not retried
        assert svc.audit is not None
        (row,) = svc.audit.latest(5)
        assert (row.outcome, row.fault, row.raw_value) == ("rejected", 17, 750)
        assert row.old_value == before * 10
        assert row.detail == error["text"]


async def test_outside_the_limits_the_drive_describes_is_422_and_nothing_is_sent(
    tmp_path: Path,
) -> None:
    # the catalog gives 3-41 no maximum; the drive describes its own (AK 4, element 8)
    async with service(tmp_path) as svc:
        drive = svc.sim.drives[1]
        highest = drive.params.specs[341].maximum
        assert highest is not None
        r = await svc.put("fan1", "3-41", {"value": highest + 1})
        assert r.status_code == 422, r.text
        assert r.json()["error"]["kind"] == "invalid_value"
        assert f"{highest:g}" in r.json()["error"]["message"]
        assert svc.audit_writer.for_pnu(1, 341) == []  # not even the read before a change
        assert drive.value(341) == 500
        r = await svc.put("fan1", "3-41", {"value": highest})  # the limit itself is allowed
        assert r.status_code == 200, r.text


async def test_limits_given_for_element_0_hold_for_the_parameter_that_is_no_array(
    tmp_path: Path,
) -> None:
    """3-41 is no array in its catalog: 3-41[0] is 3-41 itself (the same telegram), so the
    limits the configuration gives 3-41[0] hold for a write of 3-41 without an index."""
    drives = fc_drives(writable=["3-41"])[:1]
    drives[0]["parameters"] = {"3-41[0]": "{min: 1, max: 60}"}
    async with service(tmp_path, fc=drives) as svc:
        drive = svc.sim.drives[1]
        before = drive.value(341)
        for value, index in ((61, None), (0.5, None), (61, 0)):
            body: dict[str, object] = {"value": value}
            if index is not None:
                body["index"] = index
            r = await svc.put("fan1", "3-41", body)
            assert r.status_code == 422, (body, r.text)
            assert r.json()["error"]["kind"] == "invalid_value"
        assert svc.audit_writer.for_pnu(1, 341) == []  # nothing sent
        assert drive.value(341) == before
        r = await svc.put("fan1", "3-41", {"value": 60})  # the limit itself is allowed
        assert r.status_code == 200, r.text
        assert drive.value(341) == 6000


async def test_outside_the_drives_own_limits_is_409_with_fault_2(tmp_path: Path) -> None:
    # not described (describe: off): only the drive knows its maximum of 3-41 and refuses
    drives = [{**d, "describe": "off"} for d in fc_drives()]
    async with service(tmp_path, fc=drives) as svc:
        r = await svc.put("fan1", "3-41", {"value": 5000})
        assert r.status_code == 409, r.text
        assert r.json()["error"]["fault"] == 2
        assert svc.sim.drives[1].value(341) == 500
        assert svc.audit_writer.descriptions == []
        assert svc.audit is not None
        assert svc.audit.latest(1)[0].outcome == "rejected"


async def test_dead_drive_is_504(tmp_path: Path) -> None:
    async with service(tmp_path, fc=fc_drives(polls=POLLED_WRITABLES)) as svc:
        svc.sim.kill(2)
        r = await svc.put("fan2", "3-41", {"value": 20})
        assert r.status_code == 504, r.text
        assert r.json()["error"]["kind"] == "timeout"
        assert svc.audit is not None
        (row,) = svc.audit.latest(5)
        assert row.outcome == "not_sent"  # the read before the change got no answer
        assert row.old_value == 5  # the latest polled value, from before the drive died
        assert row.raw_value == 2000
        # the other drives are not disturbed
        r = await svc.put("fan1", "3-41", {"value": 20})
        assert r.status_code == 200


async def test_a_write_whose_client_goes_away_is_still_audited(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        assert svc.audit is not None
        audit = svc.audit
        task = asyncio.create_task(svc.put("fan1", "3-42", {"value": 7}))
        loop = asyncio.get_running_loop()
        end = loop.time() + 20
        while not audit.latest(1) and loop.time() < end:
            await asyncio.sleep(0)
        task.cancel()
        while audit.latest(1)[0].outcome == "pending" and loop.time() < end:
            await asyncio.sleep(0.01)
        row = audit.latest(1)[0]
        assert row.outcome == "ok", row
        assert svc.sim.drives[1].value(342) == 700


async def test_a_parameter_not_described_yet_is_503_and_nothing_is_sent(tmp_path: Path) -> None:
    """While the drive describes a parameter (at start, or when it is another drive now), a
    write or read of it would be scaled as the catalog says: refused until it has."""
    async with service(tmp_path) as svc:
        decoding = svc.runtime.snapshot.decoding["fan1"]
        decoding.pending.add(341)  # as the service marks it while the drive describes 3-41
        written = await svc.put("fan1", "3-41", {"value": 10})
        read = await svc.client.get("/api/v1/drives/fan1/parameters/3-41")
        decoding.pending.discard(341)
        after = await svc.put("fan1", "3-41", {"value": 10})
        assert svc.audit is not None
        outcomes = [row.outcome for row in svc.audit.latest(2)]
    for r in (written, read):
        assert r.status_code == 503, r.text
        assert r.json()["error"]["kind"] == "not_described"
        assert "3-41" in r.json()["error"]["message"]
    assert after.status_code == 200, after.text
    assert len(svc.audit_writer.writes(1, 341)) == 1  # only the one after it was described
    assert outcomes == ["ok", "not_sent"]


async def test_a_change_whose_read_the_drive_refuses_is_not_sent(tmp_path: Path) -> None:
    """3-42 is no array: the drive refuses the read of 3-42[135] before the change, and the
    change never goes out (it went out some 2,000 times before, its refusal taken for the
    read's repeated, until its deadline)."""
    async with service(tmp_path) as svc:
        r = await svc.put("fan2", "3-42", {"value": 10, "index": 135})
        assert r.status_code == 409, r.text
        assert r.json()["error"]["kind"] == "rejected"
        assert svc.audit_writer.writes(2, 342) == []
        (read,) = svc.audit_writer.for_pnu(2, 342)
        assert read.command is Command.READ and read.subindex == 135
        assert svc.audit is not None
        assert svc.audit.latest(1)[0].outcome == "rejected"


async def test_a_drive_down_since_the_start_says_so_rather_than_try_again_soon(
    tmp_path: Path,
) -> None:
    """A drive that never answered has described nothing: its reads and writes answer 503
    not_described, saying it is down (a few seconds would not do), and nothing is sent."""
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.002), catalog="danfoss-fc",
                    seed=11, model=STEADY)  # fmt: skip
    sim.kill(2)
    drives = fc_drives(polls=[("16-13", "50ms")])
    async with service(tmp_path, fc=drives, keep={"fc": sim}, ready=False) as svc:
        await until(lambda: not svc.runtime.snapshot.drives["fan2"].up)
        await until(lambda: not svc.runtime.snapshot.decoding["fan1"].pending)
        before = len(svc.audit_writer.for_pnu(2, 341))
        for r in (await svc.client.get("/api/v1/drives/fan2/parameters/3-41"),
                  await svc.put("fan2", "3-41", {"value": 12})):  # fmt: skip
            assert r.status_code == 503, r.text
            error = r.json()["error"]
            assert error["kind"] == "not_described"
            assert "fan2 is down" in error["message"] and "few seconds" not in error["message"]
        assert len(svc.audit_writer.for_pnu(2, 341)) == before
        r = await svc.client.get("/api/v1/drives/fan1/parameters/3-41")  # the other: as ever
        assert r.status_code == 200, r.text
