"""The planner asks drives to describe their parameters (AK 4) before their polls, on a fake
clock: polls wait for the description and are decoded as it says; a drive that leaves its
description requests unanswered keeps the catalog after a bounded number of tries and is
asked again later; another drive's polling goes on meanwhile."""

from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

from pkwbus.catalog import load_catalog
from pkwbus.catalog.description import ParameterDescription
from pkwbus.catalog.precedence import Layers
from pkwbus.master.describing import ASK_AGAIN, UNANSWERED_AT_MOST
from pkwbus.master.drive_identity import DescriptionBook
from pkwbus.master.outcomes import Answered
from pkwbus.master.plan import Described, DescribeTarget, DriveSpec, Finished, PollSpec, Send
from pkwbus.master.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import ErrorKind, ExchangeResult, Failure
from pkwbus.protocol import pkw
from pkwbus.protocol.descriptions import DescriptionForm, elements_to_read
from pkwbus.protocol.dialects import Command
from pkwbus.protocol.telegram import Telegram
from pkwbus.sim import SimTiming, Simulator
from tests.master.test_planner import TIMEOUT, FakeLine

CURRENT = 1614  # 16-14, in the catalog with conversion index -2


def spec(address: int, *, describe: bool) -> DriveSpec:
    target = DriveTarget.create("fc", address)
    entry = load_catalog("danfoss-fc").get(CURRENT)
    catalog = ParameterDescription.from_spec(entry)
    layers = Layers(catalog, catalog=catalog) if describe else None
    request = pkw.read(target.dialect, CURRENT)
    poll = PollSpec("16-14", 0, request, 0.1, catalog, layers)
    if not describe:
        return DriveSpec(f"d{address}", target, (poll,))
    wanted = DescribeTarget(CURRENT, "16-14", elements_to_read(limits=False), catalog)
    return DriveSpec(f"d{address}", target, (poll,), (wanted,), DescriptionForm.DANFOSS_FC)


class SilentOnDescriptions(FakeLine):
    """A line whose drive 1 answers everything but description requests."""

    def answer(self, send: Send) -> ExchangeResult:
        request = next(
            e for e in self.sim.deframer().feed(send.telegram) if isinstance(e, Telegram)
        )
        ak = (request.data[0] >> 4) if request.adr & 0x1F == 1 else 0
        if send.drive == "d1" and ak == send.target.dialect.request_id(Command.READ_DESCRIPTION):
            self.now += TIMEOUT
            return Failure(ErrorKind.TIMEOUT, "no answer")
        return super().answer(send)


def line(cls: type[FakeLine] = FakeLine) -> FakeLine:
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    planner = Planner([spec(1, describe=True), spec(2, describe=False)], poll_deadline=0.5)
    return cls(planner, sim)


def polls_of(fake: FakeLine, drive: str) -> list[Finished]:
    return [
        e for e in fake.events
        if isinstance(e, Finished) and e.drive == drive and isinstance(e.work, PollSpec)
    ]  # fmt: skip


def factor(poll: Finished) -> Fraction:
    assert isinstance(poll.work, PollSpec)
    return poll.work.fmt.scaling.factor


def test_polls_wait_for_the_description_and_are_decoded_as_it_says() -> None:
    fake = line()
    drive = fake.sim.drives[1]
    drive.params.specs[CURRENT] = replace(drive.params.specs[CURRENT], conversion=-3)
    fake.run(1.0)
    described = [e for e in fake.events if isinstance(e, Described) and e.drive == "d1"]
    assert len(described) == 1 and described[0].description is not None
    first = fake.events.index(described[0])
    polls = polls_of(fake, "d1")
    assert polls and all(fake.events.index(p) > first for p in polls)
    assert all(
        isinstance(p.work, PollSpec) and p.work.fmt.scaling.factor == Fraction(1, 1000)
        for p in polls
    )
    # The four elements went out before any poll of 16-14, and drive 2 polled meanwhile.
    asked = [s for s in fake.sent if s.drive == "d1"]
    assert len(asked) > 4
    assert polls_of(fake, "d2")


def test_a_drive_silent_on_descriptions_keeps_the_catalog_and_is_asked_again() -> None:
    fake = line(SilentOnDescriptions)
    fake.run(10.0)
    described = [e for e in fake.events if isinstance(e, Described) and e.drive == "d1"]
    assert len(described) == 1
    (done,) = described
    assert done.description is None and done.unanswered
    polls = [p for p in polls_of(fake, "d1") if isinstance(p.outcome, Answered)]
    assert polls, "its values flow with the catalog's description"
    assert all(
        isinstance(p.work, PollSpec) and p.work.fmt.scaling.factor == Fraction(1, 100)
        for p in polls
    )
    tried = sum(1 for r in fake.results if isinstance(r, Failure))
    assert tried <= UNANSWERED_AT_MOST * 3  # each request with its retries, then no more
    before = len(fake.sent)
    fake.run(ASK_AGAIN)
    again = [
        s for s in fake.sent[before:]
        if s.drive == "d1" and s.telegram[3] >> 4 == 4  # AK 4 (FC PKE high nibble)
    ]  # fmt: skip
    assert again, "asked again later"
    assert polls_of(fake, "d2")


def described_spec(address: int, book: DescriptionBook) -> DriveSpec:
    return replace(spec(address, describe=True), book=book)


def ak4(fake: FakeLine, drive: str | None = None) -> list[Send]:
    return [
        s for s in fake.sent
        if (drive is None or s.drive == drive) and s.telegram[3] >> 4 == 4
    ]  # fmt: skip


def test_drives_of_one_kind_are_described_once() -> None:
    book = DescriptionBook()
    sim = Simulator("fc", [1, 2, 3], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    for drive in sim.drives.values():
        drive.params.specs[CURRENT] = replace(drive.params.specs[CURRENT], conversion=-3)
    planner = Planner([described_spec(a, book) for a in (1, 2, 3)], poll_deadline=0.5)
    fake = FakeLine(planner, sim)
    fake.run(2.0)
    assert len(ak4(fake)) == len(elements_to_read(limits=False))  # one drive asked, once
    for name in ("d1", "d2", "d3"):
        polls = polls_of(fake, name)
        assert polls and {factor(p) for p in polls} == {Fraction(1, 1000)}, name


def test_another_drive_of_the_kind_describes_when_the_first_goes_away() -> None:
    book = DescriptionBook()
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    planner = Planner([described_spec(a, book) for a in (1, 2)], poll_deadline=0.5)
    fake = FakeLine(planner, sim)
    while not ak4(fake):
        fake.step(fake.now + 1.0)
    (first,) = ak4(fake)
    sim.kill(int(first.drive[1:]))  # the drive that claimed the description goes away
    fake.run(5.0)
    other = "d2" if first.drive == "d1" else "d1"
    assert len(ak4(fake, other)) == len(elements_to_read(limits=False))
    assert polls_of(fake, other)
