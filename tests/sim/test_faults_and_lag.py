"""Each fault knob does what it says (measured over many telegrams), and PKW lag in both modes."""

from __future__ import annotations

from collections import Counter

import pytest

from pkwbus.protocol import pkw
from pkwbus.protocol.pkw import NoResponse, ValueResponse, Width
from pkwbus.protocol.pkw.dialects import FC, USS, IndLayout
from pkwbus.protocol.serial.telegram import Deframer, Telegram, fc_adr, fc_lengths, uss_lengths
from pkwbus.sim import ModelConfig, SimFaults, SimTiming, Simulator
from pkwbus.sim.drives.faults import Answer
from tests.sim.conftest import FakeClock, request_telegram

QUIET = ModelConfig(noise=0.0, warning_rate=0.0, trip_rate=0.0)
N = 2000
TOLERANCE = 0.04


def classify(answer: Answer | None, adr: int) -> str:
    """What a master would make of an answer, judged with the protocol's deframer."""
    if answer is None:
        return "silence"
    if answer.late:
        return "late"
    deframer = Deframer(fc_lengths())
    events = deframer.feed(answer.data) + deframer.flush()
    telegrams = [e for e in events if isinstance(e, Telegram)]
    kinds = {type(e).__name__ for e in events if not isinstance(e, Telegram)}
    if not telegrams:
        return "bad_checksum" if "BadChecksum" in kinds else "truncated"
    if telegrams[0].adr != adr:
        return "wrong_address"
    return "garbage" if "Skipped" in kinds else "ok"


@pytest.mark.parametrize(
    ("knob", "seen"),
    [
        ("drop", "silence"),
        ("corrupt", "bad_checksum"),
        ("truncate", "truncated"),
        ("garbage", "garbage"),
        ("wrong_address", "wrong_address"),
        ("late", "late"),
    ],
)
def test_fault_rate_is_measured_as_set(knob: str, seen: str) -> None:
    sim = Simulator("fc", [1], faults=SimFaults(**{knob: 0.2}), seed=42, clock=FakeClock())
    tg = Telegram(fc_adr(1), request_telegram(fc_adr(1), pkw.read(FC, 1613), FC)[3:-1])
    outcomes = Counter(classify(sim.answer(tg), tg.adr) for _ in range(N))
    assert set(outcomes) == {"ok", seen}
    assert abs(outcomes[seen] / N - 0.2) <= TOLERANCE
    assert sim.stats.as_dict()["injected"][knob] == outcomes[seen]


def test_stale_fault_repeats_the_previous_answer() -> None:
    sim = Simulator("fc", [1], faults=SimFaults(stale=0.3), seed=5, model=QUIET, clock=FakeClock())
    stale = 0
    for raw in range(1, N + 1):
        answer = sim.handle(request_telegram(1, pkw.write(FC, 341, raw, Width.DWORD), FC))
        assert answer is not None
        resp = pkw.decode_response(answer[3:11], FC, IndLayout.USS)
        assert isinstance(resp, ValueResponse)
        if resp.raw != raw:
            assert resp.raw < raw  # an earlier answer, never an invented one
            stale += 1
    assert abs(stale / N - 0.3) <= TOLERANCE
    assert sim.stats.as_dict()["injected"]["stale"] == stale


def test_late_answer_is_marked_with_its_delay() -> None:
    sim = Simulator("fc", [1], faults=SimFaults(late=1.0, late_seconds=0.25), clock=FakeClock())
    tg = Telegram(1, request_telegram(1, pkw.read(FC, 1613), FC)[3:-1])
    answer = sim.answer(tg)
    assert answer is not None and answer.late == 0.25


def test_dead_drive_kill_and_revive_and_per_drive_faults() -> None:
    sim = Simulator("fc", [1, 2, 3], faults=SimFaults(dead=frozenset({3})), clock=FakeClock())
    req = pkw.read(FC, 1613)
    assert sim.handle(request_telegram(3, req, FC)) is None
    sim.kill(1)
    assert sim.handle(request_telegram(1, req, FC)) is None
    sim.revive(1)
    assert sim.handle(request_telegram(1, req, FC)) is not None
    sim.set_faults(2, SimFaults(drop=1.0))
    assert sim.handle(request_telegram(2, req, FC)) is None
    assert sim.handle(request_telegram(1, req, FC)) is not None
    sim.set_faults(2, None)
    assert sim.handle(request_telegram(2, req, FC)) is not None
    sim.revive(3)  # dead from the start: comes back too
    assert sim.handle(request_telegram(3, req, FC)) is not None
    stats = sim.stats.as_dict()
    assert stats["injected"]["dead"] == 2 and stats["injected"]["drop"] == 1
    assert stats["per_drive"]["2"]["injected"]["drop"] == 1


def test_probabilities_cannot_add_up_beyond_one() -> None:
    with pytest.raises(ValueError):
        SimFaults(drop=0.6, corrupt=0.5)


# ---------------------------------------------------------------------- lag


def read_pkw(sim: Simulator, req: pkw.PkwRequest) -> pkw.PkwResponse:
    answer = sim.handle(request_telegram(1, req, USS))
    assert answer is not None
    return pkw.decode_response(answer[3:11], USS, IndLayout.USS)


def test_lag_in_telegrams_answers_ak_0_meanwhile() -> None:
    timing = SimTiming(lag_telegrams=3, lag_mode="none")
    sim = Simulator("uss", [1], timing=timing, seed=1, model=QUIET, clock=FakeClock())
    req = pkw.read(USS, 1082)
    answers = [read_pkw(sim, req) for _ in range(5)]
    assert all(isinstance(a, NoResponse) and a.ak == 0 for a in answers[:3])
    assert isinstance(answers[3], ValueResponse) and pkw.matches(req, answers[3], USS)
    assert isinstance(answers[4], NoResponse)  # a repeated request is a new job
    assert sim.stats.as_dict()["lagged"] == 4


def test_lag_in_stale_mode_repeats_the_previous_answer() -> None:
    timing = SimTiming(lag_telegrams=2, lag_mode="stale")
    sim = Simulator("uss", [1], timing=timing, seed=1, model=QUIET, clock=FakeClock())
    first, second = pkw.read(USS, 1082), pkw.read(USS, 1120)
    while not pkw.matches(first, read_pkw(sim, first), USS):
        pass
    meanwhile = [read_pkw(sim, second) for _ in range(2)]
    assert all(pkw.matches(first, m, USS) and not pkw.matches(second, m, USS) for m in meanwhile)
    assert pkw.matches(second, read_pkw(sim, second), USS)


def test_lag_in_time() -> None:
    clock = FakeClock()
    timing = SimTiming(lag_seconds=0.05)
    sim = Simulator("uss", [1], timing=timing, seed=1, model=QUIET, clock=clock)
    req = pkw.read(USS, 1082)
    for _ in range(10):
        assert isinstance(read_pkw(sim, req), NoResponse)
        clock.advance(0.004)
    clock.advance(0.02)
    assert pkw.matches(req, read_pkw(sim, req), USS)


def test_broadcast_write_is_never_lagged() -> None:
    timing = SimTiming(lag_telegrams=5)
    sim = Simulator("uss", [1, 2], timing=timing, seed=1, model=QUIET, clock=FakeClock())
    req = pkw.write(USS, 1120, 0x41200000, Width.DWORD)  # 10.0 s as f32
    tg = request_telegram(0x20, req, USS)
    assert sim.handle(tg) is None
    assert [d.value(1120) for d in sim.drives.values()] == [0x41200000] * 2
    assert uss_lengths([sim.shape]) == sim.lengths
