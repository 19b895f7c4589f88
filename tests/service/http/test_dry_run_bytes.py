"""A dry run shows the bytes the line then sends: its request as the drive's carrier builds it
(FC and USS: the whole telegram, a learned PKW length included; a PROFIBUS PKW slot: the
PPO-write; data record 47: the request, whose reference each request takes as it is sent,
said beside it)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pkwbus.protocol.profidrive.drive import decode_request
from pkwbus.protocol.profidrive.parameters import RequestId
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.sim import Simulator
from tests.service.assembly.test_dp_service import TOKEN as PPO_TOKEN
from tests.service.assembly.test_dp_service import dp_service as ppo_service
from tests.service.assembly.test_ds47_service import TOKEN as DP_TOKEN
from tests.service.assembly.test_ds47_service import service as dp_service
from tests.service.http.conftest import USS_DRIVES, service


def heard(sim: Simulator) -> list[bytes]:
    """Every request telegram that reaches the simulated line from now on, as it came."""
    seen: list[bytes] = []
    original = sim.answer

    def answer(telegram: Telegram, now: float | None = None) -> Any:
        seen.append(telegram.encode())
        return original(telegram, now)

    sim.answer = answer  # type: ignore[method-assign]
    return seen


@pytest.mark.parametrize(
    ("protocol", "drive", "parameter", "value"),
    [("fc", "fan2", "3-41", 12.5), ("uss", "pump1", "p1120", 7.5)],
)
async def test_a_dry_runs_telegram_is_the_one_the_line_then_sends(
    tmp_path: Path, protocol: str, drive: str, parameter: str, value: float
) -> None:
    uss = USS_DRIVES if protocol == "uss" else None
    async with service(tmp_path, uss=uss) as svc:
        dry = await svc.put(drive, parameter, {"value": value, "dry_run": True})
        assert dry.status_code == 200, dry.text
        shown = bytes.fromhex(dry.json()["telegram"])
        assert dry.json()["telegram_note"] is None  # nothing of it is decided when sent
        sent = heard(svc.sims[protocol])
        assert shown not in sent
        done = await svc.put(drive, parameter, {"value": value})
        assert done.status_code == 200, done.text
        assert done.json()["telegram"] == dry.json()["telegram"]
        assert shown in sent, "the dry run showed bytes the line did not send"


async def test_a_record_47_dry_run_shows_the_request_and_says_its_reference_is_taken_when_sent(
    tmp_path: Path,
) -> None:
    auth = {"Authorization": f"Bearer {DP_TOKEN}"}
    url = "/api/v1/drives/pump/parameters/p1121"
    async with dp_service(tmp_path) as svc:
        dry = await svc.client.put(url, json={"value": 12.15, "dry_run": True}, headers=auth)
        assert dry.status_code == 200, dry.text
        shown = bytes.fromhex(dry.json()["telegram"])
        note = dry.json()["telegram_note"]
        assert f"reference {shown[0]} " in note and "as it is sent" in note
        before = len(svc.record_writes(9))
        done = await svc.client.put(url, json={"value": 12.15}, headers=auth)
        assert done.status_code == 200, done.text
        changes = [
            data
            for data in svc.record_writes(9)[before:]
            if decode_request(data).request_id is RequestId.CHANGE
        ]
        assert len(changes) == 1
        (sent,) = changes
        # All but the reference, which the request took as it went out.
        assert sent[1:] == shown[1:]
        assert decode_request(sent).reference == sent[0]


async def test_a_ppo_dry_run_shows_the_ppo_write_its_slot_then_sends(tmp_path: Path) -> None:
    auth = {"Authorization": f"Bearer {PPO_TOKEN}"}
    url = "/api/v1/drives/pump/parameters/3-41"
    async with ppo_service(tmp_path) as svc:
        dry = await svc.client.put(url, json={"value": 7.25, "dry_run": True}, headers=auth)
        assert dry.status_code == 200, dry.text
        assert dry.json()["telegram_note"] is None
        shown = bytes.fromhex(dry.json()["telegram"])
        before = len(svc.wire.frames)
        assert shown not in [f.data for f in svc.wire.data_exchanges() if f.da == 9]
        done = await svc.client.put(url, json={"value": 7.25}, headers=auth)
        assert done.status_code == 200, done.text
        sent = [f.data for f in svc.wire.frames[before:] if f.dsap is None and f.da == 9]
        assert shown in sent, "the dry run showed a PPO-write the slot did not send"
