"""Write options: store ram|eeprom, verify (read back), dry_run (the telegram, nothing sent)."""

from __future__ import annotations

from functools import reduce
from pathlib import Path

import pytest

from pkwbus.protocol.pkw import PkwRequest, PkwResponse
from tests.service.http.conftest import POLLED_WRITABLES, fc_drives, service


def fc_telegram(address: int, ak: int, pnu: int, raw: int) -> str:
    """An FC parameter telegram built by hand from the protocol description.

    STX, LGE (data + ADR + BCC), ADR (0x80 | address), PKE = AK << 12 | PNU,
    IND, PWE high, PWE low, control word 0 (no control), reference 0, BCC
    (XOR of all bytes before it).
    """
    data = b"".join(
        w.to_bytes(2, "big") for w in (ak << 12 | pnu, 0, raw >> 16, raw & 0xFFFF, 0, 0)
    )
    head = bytes([0x02, len(data) + 2, 0x80 | address]) + data
    bcc = reduce(lambda a, b: a ^ b, head)
    return (head + bytes([bcc])).hex(" ")


@pytest.mark.parametrize(("store", "ak"), [("ram", 3), ("eeprom", 13)])
async def test_dry_run_shows_the_telegram_and_sends_nothing(
    tmp_path: Path, store: str, ak: int
) -> None:
    async with service(tmp_path) as svc:
        body = {"value": 12.5, "store": store, "dry_run": True}
        r = await svc.put("fan2", "3-41", body)
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["dry_run"] is True
        assert out["raw"] == 1250
        assert out["telegram"] == fc_telegram(2, ak, 341, 1250)
        assert svc.audit_writer.for_pnu(2, 341) == []
        assert svc.sim.drives[2].value(341) == 500
        assert svc.audit is not None
        (row,) = svc.audit.latest(5)
        assert (row.outcome, row.raw_value, row.new_value, row.store) == (
            "dry_run",
            1250,
            12.5,
            store,
        )


async def test_dry_run_is_still_checked(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        r = await svc.put("fan1", "3-41", {"value": -5, "dry_run": True})
        assert r.status_code == 422
        r = await svc.put("fan1", "3-41", {"value": 5, "dry_run": True}, headers={})
        assert r.status_code == 401
        assert svc.audit_writer.for_pnu(1, 341) == []


async def test_store_ram_and_eeprom(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        drive = svc.sim.drives[1]
        r = await svc.put("fan1", "3-41", {"value": 8})
        assert r.status_code == 200, r.text
        assert r.json()["store"] == "ram"
        assert drive.value(341) == 800
        assert (341, 0) not in drive.eeprom
        r = await svc.put("fan1", "3-42", {"value": 9.5, "store": "eeprom"})
        assert r.status_code == 200, r.text
        assert r.json()["store"] == "eeprom"
        assert drive.value(342) == 950
        assert drive.eeprom[342, 0] == 950
        (write,) = svc.audit_writer.writes(1, 342)
        assert write.ak == 13


async def test_verify_reads_back(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:
        r = await svc.put("fan1", "3-41", {"value": 7.25, "verify": True})
        assert r.status_code == 200, r.text
        out = r.json()
        # 3-41 is not polled here: no old value. The change goes out after a read of
        # its parameter (the answer a lagging drive would repeat), and is read back.
        assert (out["verified"], out["value"], out["old_value"]) == (True, 7.25, None)
        requests = [req.command.name for req in svc.audit_writer.for_pnu(1, 341)]
        assert requests == ["READ", "WRITE_DWORD", "READ"]
        assert svc.audit is not None
        assert svc.audit.latest(1)[0].outcome == "ok"


async def test_verify_reports_a_mismatch(tmp_path: Path) -> None:
    """A drive that keeps another value than the one it acknowledged (it clamps, say)."""
    async with service(tmp_path) as svc:
        drive = svc.sim.drives[3]

        def clamp(address: int, req: PkwRequest, resp: PkwResponse) -> None:
            if address == 3 and req.is_write and req.pnu == 342:
                drive.set_value(342, 300)

        svc.audit_writer.after.append(clamp)
        r = await svc.put("fan3", "3-42", {"value": 4, "verify": True})
        assert r.status_code == 200, r.text
        assert r.json()["verified"] is False
        assert svc.audit is not None
        row = svc.audit.latest(1)[0]
        assert row.outcome == "mismatch"
        assert "3" in (row.detail or "")


async def test_verify_without_an_answer_is_not_verified(tmp_path: Path) -> None:
    async with service(tmp_path) as svc:

        def die(address: int, req: PkwRequest, resp: PkwResponse) -> None:
            if address == 1 and req.is_write:
                svc.sim.kill(1)

        svc.audit_writer.after.append(die)
        r = await svc.put("fan1", "3-41", {"value": 6, "verify": True})
        # the write was answered (the drive died after answering it); the read-back was not
        assert r.status_code == 200, r.text
        assert r.json()["verified"] is False
        assert svc.audit is not None
        assert svc.audit.latest(1)[0].outcome == "unverified"


async def test_a_dry_run_says_the_value_it_would_change(tmp_path: Path) -> None:
    """The old value of a dry run is the latest the drive confirmed, as a write's is: in the
    answer and in its audit row."""
    async with service(tmp_path, fc=fc_drives(polls=POLLED_WRITABLES)) as svc:
        held = svc.sim.drives[2].value(341) / 100  # 3-41 in s, conversion -2
        r = await svc.put("fan2", "3-41", {"value": 12.5, "dry_run": True})
        assert r.status_code == 200, r.text
        assert r.json()["old_value"] == held
        assert svc.audit is not None
        (row,) = svc.audit.latest(5)
        assert (row.outcome, row.old_value) == ("dry_run", held)
