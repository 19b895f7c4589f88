"""The writer's checks against made-up answers of the service and the simulators."""

from __future__ import annotations

import json
from typing import Any

import httpx

from .plan import soak_lines
from .traffic import Problems, Writer

LINES = soak_lines(1)  # one FC line: two drives with two writable parameters each


class Fake:
    """A service that answers writes with ``status`` and keeps audit rows as told, and
    simulators whose drives hold what ``held`` says."""

    def __init__(self, status: int = 200, outcome: str = "ok", audit: bool = True) -> None:
        self.status, self.outcome, self.audit = status, outcome, audit
        self.rows: list[dict[str, Any]] = []
        self.held: dict[tuple[str, str], float] = {}

    def service(self, request: httpx.Request) -> httpx.Response:
        if request.method == "PUT":
            drive, parameter = request.url.path.split("/")[4::2]
            value = json.loads(request.content)["value"]
            if self.audit:
                self.rows.append({"id": len(self.rows) + 1, "drive": drive,
                                  "parameter": parameter, "new_value": value,
                                  "outcome": self.outcome})  # fmt: skip
            if self.status == 200:
                self.held[drive, parameter] = value
            return httpx.Response(self.status, json={})
        return httpx.Response(200, json=list(reversed(self.rows)))

    def sims(self, request: httpx.Request) -> httpx.Response:
        query = request.url.params
        drive = next(d.name for d in LINES[0].drives if d.address == int(query["address"]))
        return httpx.Response(200, json={"value": self.held.get((drive, query["parameter"]), 5.0)})

    def writer(self) -> tuple[Writer, Problems]:
        problems = Problems()
        service = httpx.AsyncClient(
            transport=httpx.MockTransport(self.service), base_url="http://s"
        )
        sims = httpx.AsyncClient(transport=httpx.MockTransport(self.sims), base_url="http://m")
        return Writer(LINES, service, sims, "t", problems), problems


async def write(fake: Fake, times: int) -> Problems:
    writer, problems = fake.writer()
    for _ in range(times):
        await writer.one()
    await writer.check_audit()
    await writer.check_held()
    return problems


async def test_writes_held_and_audited_pass() -> None:
    assert (await write(Fake(), 10)).found == []


async def test_a_write_without_its_audit_row_is_found() -> None:
    problems = await write(Fake(audit=False), 3)
    assert problems.counts == {"unaudited": 3}


async def test_an_audit_row_of_a_write_nobody_made_is_found() -> None:
    fake = Fake()
    fake.rows.append({"id": 1, "drive": "fc0_d1", "parameter": "3-41", "new_value": 99.0,
                      "outcome": "ok"})  # fmt: skip
    problems = await write(fake, 2)
    assert problems.counts == {"invented": 1}


async def test_an_audit_outcome_that_contradicts_the_answer_is_found() -> None:
    problems = await write(Fake(status=504, outcome="ok"), 2)
    assert problems.counts == {"outcome": 2}


async def test_a_write_answered_200_that_the_drive_does_not_hold_is_found() -> None:
    fake = Fake()
    writer, problems = fake.writer()
    await writer.one()
    fake.held.clear()  # the drive lost it
    await writer.check_held()
    assert problems.counts == {"held": 1}


async def test_an_unexpected_answer_to_a_write_is_found() -> None:
    problems = await write(Fake(status=500, outcome="error"), 1)
    assert problems.counts["status"] == 1


async def test_a_write_cut_off_by_the_soaks_end_may_have_no_row_or_one_without_its_value() -> None:
    # Cut off before it was sent: no row. Cut off while its body was on the way: the
    # service audits an unreadable request (outcome invalid, no value).
    for row in (None, {"new_value": None, "outcome": "invalid"}):
        fake = Fake(audit=False)
        writer, problems = fake.writer()
        await writer.one()
        writer.writes[-1].status = 0  # as if its PUT had been cancelled
        if row is not None:
            fake.rows.append({"id": 1, "drive": writer.writes[-1].drive.name,
                              "parameter": writer.writes[-1].parameter, **row})  # fmt: skip
        await writer.check_audit()
        assert problems.counts == {}, row
    # Answered, a write without its row is a problem.
    problems = await write(Fake(audit=False), 1)
    assert problems.counts == {"unaudited": 1}


async def test_a_write_cut_off_by_the_soaks_end_may_have_a_pending_row() -> None:
    # The soak cancels its writer at the end: a write whose PUT never returned has no
    # answer to hold its row against; the service completes the row later.
    fake = Fake(outcome="pending")
    writer, problems = fake.writer()
    await writer.one()
    writer.writes[-1].status = 0  # as if its PUT had been cancelled
    await writer.check_audit()
    assert problems.counts == {}
    # Answered, the same pending row is a problem.
    fake = Fake(outcome="pending")
    writer, problems = fake.writer()
    await writer.one()
    await writer.check_audit()
    assert problems.counts == {"outcome": 1}
