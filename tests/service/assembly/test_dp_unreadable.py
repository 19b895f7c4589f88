"""A slave whose PPO-reads hold no PKW answer of its dialect (set to another PPO or
dialect): its jobs still go out and end with why, the log says it once, the metrics
count it, and the other slaves go on."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import pytest

from pkwbus.catalog.description import ParameterDescription
from pkwbus.master.planning.jobs import JobKind
from pkwbus.master.planning.outcomes import TimedOut
from pkwbus.protocol import pkw
from pkwbus.protocol.profibus import fdl
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.profibus.line import DpSimulator
from tests.service.assembly.test_dp_service import dp_service, until


@dataclass
class Garble:
    """While ``on``, every Data_Exchange answer of slave ``address`` is all bytes FF."""

    address: int
    on: bool = False
    count: int = 0

    def __call__(self, sim: DpSimulator) -> None:
        answer = sim.answer

        def garbled(frame: object, now: float | None = None) -> Answer | None:
            reply = answer(frame, now)
            if not self.on or reply is None or not isinstance(frame, fdl.DataFrame):
                return reply
            if frame.da != self.address or frame.dsap is not None or not frame.data:
                return reply
            found = fdl.decode(reply.data)
            if not isinstance(found, fdl.DataFrame) or not found.data:
                return reply
            self.count += 1
            ff = fdl.DataFrame(found.da, found.sa, found.fc, data=b"\xff" * len(found.data))
            return Answer(fdl.encode(ff), reply.late)

        sim.answer = garbled  # type: ignore[method-assign]


async def test_a_job_goes_out_and_ends_saying_the_answers_cannot_be_read(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    garble = Garble(9)
    async with dp_service(tmp_path, watch=garble) as svc:
        caplog.set_level(logging.INFO, logger="pkwbus.master.wires.profibus.wire")
        before = svc.sample("pkwbus_telegram_errors_total", drive="pump", kind="unexpected")
        garble.on = True
        await until(lambda: garble.count >= 30)
        sent_before = len(svc.wire.data_exchanges())
        result = await svc.runtime.submit(
            "pump",
            pkw.read_parameter(svc.sim.dialect, 1613, 0, text=False),
            JobKind.READ,
            ParameterDescription(),
        )
        assert isinstance(result.outcome, TimedOut)
        assert "no answer that can be read after 3 tries" in result.outcome.reason
        assert "no PPO 1 answer of the danfoss-pcv dialect" in result.outcome.reason
        # The request went out (the wait for AK 0 ran out): a PPO-write with its PNU.
        requests = [
            f for f in svc.wire.data_exchanges()[sent_before:]
            if f.da == 9 and int.from_bytes(f.data[:2], "big") & 0x7FF == 1613
        ]  # fmt: skip
        assert requests
        after = svc.sample("pkwbus_telegram_errors_total", drive="pump", kind="unexpected")
        assert after is not None and after >= (before or 0) + 20
        told = [r for r in caplog.records if "no PPO 1 answer" in r.getMessage()]
        assert len(told) == 1 and told[0].levelno == logging.WARNING
        # The other slaves went on meanwhile.
        reads = svc.reads("mixer")
        await until(lambda: svc.reads("mixer") > reads + 2)
        garble.on = False
        await until(lambda: any("can be read again" in r.getMessage() for r in caplog.records))
        reads = svc.reads("pump")
        await until(lambda: svc.reads("pump") > reads)
