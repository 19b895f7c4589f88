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
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.answers import ErrorKind, ExchangeResult, Failure
from pkwbus.master.planning.describing import ASK_AGAIN, UNANSWERED_AT_MOST, DriveDescriber
from pkwbus.master.planning.identity import DescriptionBook, identity_requests
from pkwbus.master.planning.outcomes import Answered, LineFailed, Outcome, TimedOut
from pkwbus.master.planning.plan import (
    Described,
    DescribeTarget,
    DriveSpec,
    Finished,
    HealthChanged,
    LeftUnanswered,
    Overrun,
    PollSpec,
    Send,
)
from pkwbus.master.planning.planner import Planner
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DescriptionForm, DriveDescription, elements_to_read
from pkwbus.protocol.pkw.dialects import Command
from pkwbus.protocol.serial.telegram import Telegram
from pkwbus.sim import SimTiming, Simulator
from tests.master.planning.test_planner import TIMEOUT, FakeLine

CURRENT = 1614  # 16-14, in the catalog with conversion index -2


def spec(address: int, *, describe: bool) -> DriveSpec:
    target = DriveTarget.create("fc", address)
    entry = load_catalog("danfoss-fc").get(CURRENT)
    catalog = ParameterDescription.from_spec(entry)
    layers = Layers(catalog, catalog=catalog) if describe else None
    request = pkw.read(target.dialect, CURRENT)
    poll = PollSpec("16-14", 0, request, 0.1, catalog, layers)
    if not describe:
        return DriveSpec(f"d{address}", carrier_for(target), (poll,))
    wanted = DescribeTarget(CURRENT, "16-14", elements_to_read(limits=False), catalog)
    return DriveSpec(
        f"d{address}", carrier_for(target), (poll,), (wanted,), DescriptionForm.DANFOSS_FC
    )


class SilentOnDescriptions(FakeLine):
    """A line whose drive 1 answers everything but description requests."""

    def answer(self, send: Send) -> ExchangeResult:
        request = next(
            e for e in self.sim.deframer().feed(send.telegram) if isinstance(e, Telegram)
        )
        ak = (request.data[0] >> 4) if request.adr & 0x1F == 1 else 0
        if send.drive == "d1" and ak == self.planner.drive(send.drive).carrier.dialect.request_id(
            Command.READ_DESCRIPTION
        ):
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
    assert isinstance(done, LeftUnanswered) and done.description is None
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


def test_a_drive_silent_on_descriptions_is_never_shown_down() -> None:
    fake = line(SilentOnDescriptions)
    fake.run(ASK_AGAIN + 10.0)
    downs = [e for e in fake.events if isinstance(e, HealthChanged) and not e.up]
    assert downs == []


def test_no_overrun_for_polls_that_waited_for_their_description() -> None:
    """Two parameters: the first one's poll (every 4 ms) waits while the second is described
    (four requests of 2 ms): late, but not an overrun: it was never due before."""
    target = DriveTarget.create("fc", 1)
    catalog = load_catalog("danfoss-fc")
    polls, wanted = [], []
    for pnu, name in ((1613, "16-13"), (1614, "16-14")):
        entry = ParameterDescription.from_spec(catalog.get(pnu))
        request = pkw.read(target.dialect, pnu)
        polls.append(PollSpec(name, 0, request, 0.004, entry, Layers(entry, catalog=entry)))
        wanted.append(DescribeTarget(pnu, name, elements_to_read(limits=False), entry))
    drive = DriveSpec(
        "d1", carrier_for(target), tuple(polls), tuple(wanted), DescriptionForm.DANFOSS_FC
    )
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    fake = FakeLine(Planner([drive], poll_deadline=0.5), sim)
    fake.run(0.1)
    assert polls_of(fake, "d1")
    assert not [e for e in fake.events if isinstance(e, Overrun)]


def test_a_drive_away_while_described_is_described_when_back_before_its_values() -> None:
    book = DescriptionBook()
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    drive = sim.drives[1]
    drive.params.specs[CURRENT] = replace(drive.params.specs[CURRENT], conversion=-3)
    fake = FakeLine(Planner([described_spec(1, book)], poll_deadline=0.5), sim)
    while not ak4(fake):  # identified; its first description request goes out
        fake.step(fake.now + 1.0)
    sim.kill(1)
    fake.run(5.0)
    assert not [p for p in polls_of(fake, "d1") if isinstance(p.outcome, Answered)]
    sim.revive(1)
    fake.run(5.0)
    answered = [p for p in polls_of(fake, "d1") if isinstance(p.outcome, Answered)]
    assert answered and {factor(p) for p in answered} == {Fraction(1, 1000)}


def describer(book: DescriptionBook | None = None) -> DriveDescriber:
    dialect = DriveTarget.create("fc", 1).dialect
    return DriveDescriber(dialect, DescriptionForm.DANFOSS_FC, [(CURRENT, (1, 2, 4, 6))],
                          book=book or DescriptionBook(),
                          identity=identity_requests(dialect))  # fmt: skip


def text(value: bytes) -> Answered:
    return Answered(pkw.TextResponse(15, 1540, 0, value))


def identify(d: DriveDescriber, *answers: Outcome) -> None:
    for answer in answers:
        step = d.next_request(0.0)
        assert step is not None and step.identity
        d.took(step, answer, 0.0)


def test_an_identity_that_cannot_be_read_keeps_the_one_known() -> None:
    d = describer()
    identify(d, text(b"FC-302"), text(b"05.11"))
    assert d.identity == "fc:FC-302|05.11"
    assert d.recheck() == []
    identify(d, TimedOut("no answer"), TimedOut("no answer"))
    assert d.identity == "fc:FC-302|05.11" and not d.changed


def test_an_identity_answer_of_before_the_drive_was_away_is_not_taken() -> None:
    d = describer()
    stale = d.next_request(0.0)
    assert stale is not None and stale.identity
    d.recheck()  # the drive was away meanwhile: the identity is read afresh
    d.took(stale, text(b"05.11"), 0.0)  # the old round's answer comes late
    identify(d, text(b"FC-302"), text(b"05.11"))
    assert d.identity == "fc:FC-302|05.11"


def test_a_lost_line_is_not_the_drive_left_unanswered() -> None:
    d = describer()
    identify(d, text(b"FC-302"), text(b"05.11"))
    for _ in range(UNANSWERED_AT_MOST + 2):
        step = d.next_request(0.0)
        assert step is not None and not step.identity
        assert d.took(step, LineFailed("the line's port is not open"), 0.0) == []
    assert d.waiting(CURRENT)


def test_a_description_read_without_limits_does_not_serve_a_write() -> None:
    book = DescriptionBook()
    book.put("fc:x", CURRENT, DriveDescription(type_code=4, conversion=-2), (1, 2, 4, 6))
    assert book.get("fc:x", CURRENT, (1, 2, 4, 6)) is not None
    assert book.get("fc:x", CURRENT, (1, 2, 4, 6, 7, 8)) is None


def test_the_book_keeps_no_limits_a_drive_may_change() -> None:
    """A writable parameter's limits are read from the drive at each start (FC 4-14 follows
    4-19): the book keeps its type and scaling for the next drive of the kind, not them."""
    book = DescriptionBook()
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    target = DriveTarget.create("fc", 1)
    entry = ParameterDescription.from_spec(load_catalog("danfoss-fc").get(341))
    wanted = DescribeTarget(341, "3-41", elements_to_read(limits=True), entry)
    drive = DriveSpec("d1", carrier_for(target), (), (wanted,), DescriptionForm.DANFOSS_FC, book)
    fake = FakeLine(Planner([drive], poll_deadline=0.5), sim)
    fake.run(1.0)
    (done,) = [e for e in fake.events if isinstance(e, Described)]
    assert done.description is not None and done.description.high_raw is not None
    (identity,) = book.entries
    kept = book.get(identity, 341)
    assert kept is not None and kept.conversion == done.description.conversion
    assert (kept.low_raw, kept.high_raw) == (None, None)
    assert book.get(identity, 341, elements_to_read(limits=True)) is None


def test_a_drive_of_a_described_kind_reads_only_its_own_limits() -> None:
    book = DescriptionBook()
    sim = Simulator("fc", [1, 2], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    entry = ParameterDescription.from_spec(load_catalog("danfoss-fc").get(341))
    wanted = DescribeTarget(341, "3-41", elements_to_read(limits=True), entry)
    drives = [
        DriveSpec(f"d{a}", carrier_for(DriveTarget.create("fc", a)), (), (wanted,),
                  DescriptionForm.DANFOSS_FC, book)
        for a in (1, 2)
    ]  # fmt: skip
    highest = sim.drives[2].params.specs[341].maximum
    assert highest is not None
    sim.drives[2].params.specs[341] = replace(sim.drives[2].params.specs[341], maximum=highest / 2)
    fake = FakeLine(Planner(drives, poll_deadline=0.5), sim)
    fake.run(1.0)
    assert len(ak4(fake)) == len(elements_to_read(limits=True)) + 2  # then 7 and 8 alone
    done = {e.drive: e.description for e in fake.events if isinstance(e, Described)}
    first, second = (done[d] for d in sorted(done, key=lambda d: len(ak4(fake, d)), reverse=True))
    assert first is not None and second is not None
    assert second.conversion == first.conversion
    assert second.high_raw is not None and first.high_raw is not None
    assert second.high_raw * 2 == first.high_raw  # each drive's own limit


POWER_UPS = 1503  # 15-03: no vendor document types it (the catalog's type is recalled)


def counter_spec(*, refuses: bool) -> tuple[DriveSpec, Simulator]:
    """Drive 1 polled for 15-03 by default: its poll needs the drive's description."""
    sim = Simulator("fc", [1], timing=SimTiming(response_delay=0.0), catalog="danfoss-fc")
    if refuses:
        params = sim.drives[1].params
        params.specs[POWER_UPS] = replace(params.specs[POWER_UPS], described=False)
    target = DriveTarget.create("fc", 1)
    catalog = ParameterDescription.from_spec(load_catalog("danfoss-fc").get(POWER_UPS))
    request = pkw.read(target.dialect, POWER_UPS)
    poll = PollSpec("15-03", 0, request, 0.1, catalog, Layers(catalog, catalog=catalog),
                    described_only=True)  # fmt: skip
    wanted = DescribeTarget(POWER_UPS, "15-03", elements_to_read(limits=False), catalog)
    spec = DriveSpec("d1", carrier_for(target), (poll,), (wanted,), DescriptionForm.DANFOSS_FC)
    return spec, sim


def test_a_poll_no_document_types_goes_out_once_the_drive_describes_its_type() -> None:
    spec, sim = counter_spec(refuses=False)
    fake = FakeLine(Planner([spec], poll_deadline=0.5), sim)
    fake.run(1.0)
    (described,) = [e for e in fake.events if isinstance(e, Described)]
    assert described.description is not None and described.description.vtype is not None
    assert described.polls and not described.withheld
    polls = [p for p in polls_of(fake, "d1") if isinstance(p.outcome, Answered)]
    assert polls, "15-03 is polled by the type the drive described"


def test_a_poll_no_document_types_is_withheld_when_the_drive_does_not_describe_it() -> None:
    spec, sim = counter_spec(refuses=True)
    fake = FakeLine(Planner([spec], poll_deadline=0.5), sim)
    fake.run(5.0)
    (described,) = [e for e in fake.events if isinstance(e, Described)]
    assert described.description is None and not described.polls
    assert [p.parameter for p in described.withheld] == ["15-03"]
    assert not polls_of(fake, "d1"), "no value read by a type nobody stated"
    reads = [s for s in fake.sent if s.telegram[3] >> 4 == 1]  # AK 1: a value read
    assert reads == []


def test_a_withheld_poll_is_asked_again_when_the_drive_comes_back() -> None:
    """A refusal may be the drive's state (booting), not its kind: after the drive was away
    its description is asked again, and its type now given releases the poll."""
    spec, sim = counter_spec(refuses=True)
    frequency = PollSpec("16-13", 0, pkw.read(spec.carrier.dialect, 1613), 0.1)
    spec = replace(spec, polls=(*spec.polls, frequency))  # its traffic tells it is away
    fake = FakeLine(Planner([spec], poll_deadline=0.5), sim)
    fake.run(2.0)
    assert not [p for p in polls_of(fake, "d1") if p.work.parameter == "15-03"]
    params = sim.drives[1].params
    params.specs[POWER_UPS] = replace(params.specs[POWER_UPS], described=True)
    sim.kill(1)
    fake.run(5.0)  # away: down, probed
    sim.revive(1)
    fake.run(70.0)  # back at the next probe (capped back-off), described, polled
    polls = [
        p for p in polls_of(fake, "d1")
        if isinstance(p.outcome, Answered) and p.work.parameter == "15-03"
    ]  # fmt: skip
    assert polls, "released by the type the drive now describes"
