"""DP-V0 services byte-exact; the per-slave state machine against every answer in every state."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.services import Diagnosis, Parameters, Service
from pkwbus.protocol.profibus.dp.slave import (
    DiagnosisRead,
    DpSlave,
    Failed,
    FailureKind,
    Garbled,
    Inputs,
    NoAnswer,
    Restarted,
    RestartReason,
    SlaveEvent,
    SlaveSetup,
    SlaveState,
    StateChanged,
)
from pkwbus.protocol.profibus.fdl import DataFrame, ShortAck, Status

# Captured from a Festo slave 8 with master 2 (pyprofibus issue 19).
DIAG_REQUEST = bytes.fromhex("68 05 05 68 88 82 6D 3C 3E F1 16")
DIAG_NOT_READY = bytes.fromhex("68 0B 0B 68 82 88 08 3E 3C 02 05 00 FF 0A 35 D1 16")
SET_PRM = bytes.fromhex(
    "68 13 13 68 88 82 5D 3D 3E B8 1E 01 00 0A 35 01 00 00 00 82 00 00 00 7B 16"
)
CHK_CFG = bytes.fromhex("68 06 06 68 88 82 7D 3E 3E 21 24 16")
DIAG_READY = bytes.fromhex("68 0B 0B 68 82 88 08 3E 3C 00 0C 00 02 0A 35 D9 16")
RS = bytes.fromhex("10 02 08 03 0D 16")

FESTO_PRM = Parameters(
    ident=0x0A35,
    watchdog=(0x1E, 0x01),
    group=1,
    user_prm=bytes.fromhex("00 00 00 82 00 00 00"),
    lock=True,
    sync=True,
    freeze=True,
)


# ------------------------------------------------------------------ services


def test_set_prm_of_the_capture() -> None:
    assert fdl.decode(SET_PRM) == dps.request(
        Service.SET_PRM, 8, 2, FESTO_PRM.encode(), fcb=False, fcv=True
    )
    assert FESTO_PRM.watchdog_seconds == pytest.approx(0.3)
    data = fdl.decode(SET_PRM)
    assert isinstance(data, DataFrame)
    assert dps.decode_parameters(data.data) == FESTO_PRM


def test_diagnosis_of_the_capture() -> None:
    frame = fdl.decode(DIAG_NOT_READY)
    assert isinstance(frame, DataFrame)
    diag = dps.decode_diagnosis(frame.data)
    assert diag.flags == {"not_ready", "prm_required"}
    assert diag.master is None and diag.ident == 0x0A35 and not diag.ready
    frame = fdl.decode(DIAG_READY)
    assert isinstance(frame, DataFrame)
    ready = dps.decode_diagnosis(frame.data)
    assert ready.flags == {"watchdog_on"} and ready.master == 2 and ready.ready
    assert not ready.owned_by_other(2) and ready.owned_by_other(3)
    assert dps.encode_diagnosis(ready) == frame.data


def test_diagnosis_too_short_is_the_peers_error() -> None:
    with pytest.raises(RemoteProtocolError, match="5 bytes"):
        dps.decode_diagnosis(b"\x00\x04\x00\xff\x0a")


def test_diagnosis_flag_names_are_checked() -> None:
    diag = Diagnosis(frozenset(), None, 1)
    with pytest.raises(LocalProtocolError, match="no diagnosis flag"):
        diag.has("cfg_falt")


def test_global_control_clear() -> None:
    assert fdl.encode(dps.global_control_clear(2)) == bytes.fromhex(
        "68 07 07 68 FF 82 46 3A 3E 02 00 41 16"
    )


@pytest.mark.parametrize(
    ("cfg", "inputs", "outputs", "count"),
    [
        ("F3 F1", 12, 12, 2),  # PPO 1
        ("F3 F5", 20, 20, 2),  # PPO 2
        ("F1", 4, 4, 1),  # PPO 3
        ("00 F1", 4, 4, 2),  # empty slot first (MICROMASTER 4)
        ("21", 0, 2, 1),  # 2 bytes out
        ("13", 4, 0, 1),  # 4 bytes in
        ("C1 C3 C3 AA", 8, 8, 1),  # special: 4 words out, 4 words in, 1 manufacturer byte
        ("41 47 AA 00", 16, 0, 2),  # special: 8 words in, 1 manufacturer byte; empty slot
        ("80 87", 0, 8, 1),  # special: 8 bytes out, consistent
    ],
)
def test_configuration_identifiers(cfg: str, inputs: int, outputs: int, count: int) -> None:
    data = bytes.fromhex(cfg)
    modules = dps.parse_cfg(data)
    assert len(modules) == count
    assert b"".join(m.raw for m in modules) == data
    assert dps.io_lengths(data) == (inputs, outputs)


def test_reserved_and_empty_configurations_are_refused() -> None:
    with pytest.raises(RemoteProtocolError, match="cut short"):
        dps.parse_cfg(b"\x82\x87")  # 2 manufacturer bytes announced, none there
    with pytest.raises(RemoteProtocolError, match="reserved"):
        dps.parse_cfg(b"\x0f")
    with pytest.raises(LocalProtocolError, match="empty"):
        dps.check_cfg(b"")
    with pytest.raises(LocalProtocolError, match="cut short"):
        dps.check_cfg(b"\x42\x87")


@settings(deadline=None)
@given(st.floats(0.01, 650.25))
def test_watchdog_factors_cover_the_time(seconds: float) -> None:
    f1, f2 = dps.watchdog_factors(seconds)
    assert 1 <= f1 <= 255 and 1 <= f2 <= 255
    ticks = f1 * f2
    assert ticks * dps.WATCHDOG_TICK >= seconds - 1e-9
    assert (ticks - f2) * dps.WATCHDOG_TICK < seconds + 1e-9  # no more than one step above


@pytest.mark.parametrize("seconds", [0.0, -1.0, 700.0])
def test_watchdog_out_of_range(seconds: float) -> None:
    with pytest.raises(LocalProtocolError, match="watchdog"):
        dps.watchdog_factors(seconds)


flags = st.frozensets(st.sampled_from(dps.DIAG_FLAGS))


@settings(deadline=None)
@given(flags, st.none() | st.integers(0, 125), st.integers(0, 0xFFFF), st.binary(max_size=20))
def test_diagnosis_round_trip(
    names: frozenset[str], master: int | None, ident: int, ext: bytes
) -> None:
    diag = Diagnosis(names, master, ident, ext)
    assert dps.decode_diagnosis(dps.encode_diagnosis(diag)) == diag


@settings(deadline=None)
@given(
    st.integers(0, 0xFFFF),
    st.none() | st.tuples(st.integers(1, 255), st.integers(1, 255)),
    st.integers(0, 255),
    st.integers(0, 255),
    st.binary(max_size=dps.MAX_USER_PRM),
    st.booleans(),
    st.booleans(),
)
def test_parameters_round_trip(
    ident: int,
    wd: tuple[int, int] | None,
    tsdr: int,
    group: int,
    user: bytes,
    lock: bool,
    sync: bool,
) -> None:
    prm = Parameters(ident, wd, tsdr, group, user, lock=lock, sync=sync)
    assert dps.decode_parameters(prm.encode()) == prm


def test_parameters_out_of_range() -> None:
    with pytest.raises(LocalProtocolError, match="min TSDR"):
        Parameters(1, min_tsdr=256).encode()
    with pytest.raises(LocalProtocolError, match="user parameter"):
        Parameters(1, user_prm=bytes(238)).encode()
    with pytest.raises(LocalProtocolError, match="ident"):
        Parameters(0x10000).encode()


# --------------------------------------------------------- the state machine

MASTER, SLAVE, OTHER = 2, 8, 5
PPO1_CFG = b"\xf3\xf1"
PRM = Parameters(ident=0x0402, watchdog=dps.watchdog_factors(0.5))


def setup(cfg: bytes = PPO1_CFG, retries: int = 1) -> SlaveSetup:
    return SlaveSetup(SLAVE, MASTER, PRM, cfg, retries=retries, probe_interval=2.0)


def answer(status: Status, data: bytes = b"", saps: bool = False) -> DataFrame:
    fc = fdl.response_fc(status)
    if saps:
        return DataFrame(MASTER, SLAVE, fc, 62, 60, data)
    return DataFrame(MASTER, SLAVE, fc, data=data)


def diag(*names: str, master: int | None = None) -> DataFrame:
    data = dps.encode_diagnosis(Diagnosis(frozenset(names), master, 0x0402))
    return answer(Status.DL, data, saps=True)


NOT_READY = diag("prm_required", "not_ready")
READY = diag("watchdog_on", master=MASTER)
LOCKED_DIAG = diag("watchdog_on", master=OTHER)


def service_of(frame: DataFrame) -> Service | None:
    return None if frame.dsap is None else Service(frame.dsap)


def bring_up(slave: DpSlave, now: float = 0.0) -> None:
    for reply in (NOT_READY, ShortAck(), ShortAck(), READY):
        assert slave.poll(now) is not None
        slave.feed(reply, now)
    assert slave.state is SlaveState.DATA_EXCHANGE


def test_start_up_reproduces_the_capture() -> None:
    festo = DpSlave(SlaveSetup(SLAVE, MASTER, FESTO_PRM, b"\x21"))
    sent: list[bytes] = []
    for reply in (DIAG_NOT_READY, b"\xe5", b"\xe5", DIAG_READY):
        frame = festo.poll(0.0)
        assert frame is not None
        sent.append(fdl.encode(frame))
        festo.feed(fdl.decode(reply), 0.0)
    assert sent[:3] == [DIAG_REQUEST, SET_PRM, CHK_CFG]
    assert fdl.decode(sent[3]) == dps.request(
        Service.SLAVE_DIAG, SLAVE, MASTER, fcb=False, fcv=True
    )
    assert festo.state is SlaveState.DATA_EXCHANGE
    frame = festo.poll(0.1, b"\x12\x34")
    assert frame == DataFrame(
        SLAVE, MASTER, fdl.request_fc(fdl.Function.SRD_HIGH, fcb=True, fcv=True), data=b"\x12\x34"
    )


def test_states_along_the_start_up() -> None:
    slave = DpSlave(setup())
    states = [slave.state]
    for reply in (NOT_READY, ShortAck(), ShortAck(), diag("not_ready", master=MASTER), READY):
        assert slave.poll(0.0) is not None
        slave.feed(reply, 0.0)
        states.append(slave.state)
    assert states == [
        SlaveState.OFFLINE,
        SlaveState.WAIT_PRM,
        SlaveState.WAIT_CFG,
        SlaveState.WAIT_CFG,
        SlaveState.WAIT_CFG,
        SlaveState.DATA_EXCHANGE,
    ]
    frame = slave.poll(0.0, bytes(12))
    assert frame is not None and service_of(frame) is None and frame.data == bytes(12)
    events = slave.feed(answer(Status.DL, bytes(range(12))), 0.0)
    assert events == [Inputs(bytes(range(12)), False)]


def test_outputs_of_the_wrong_length_are_refused() -> None:
    slave = DpSlave(setup())
    bring_up(slave)
    with pytest.raises(LocalProtocolError, match="3 output bytes"):
        slave.poll(0.0, b"abc")


def test_dh_fetches_the_diagnosis_then_exchange_goes_on() -> None:
    slave = DpSlave(setup())
    bring_up(slave)
    slave.poll(0.0)
    assert slave.feed(answer(Status.DH, bytes(12)), 0.0) == [Inputs(bytes(12), True)]
    frame = slave.poll(0.0)
    assert frame is not None and service_of(frame) is Service.SLAVE_DIAG
    slave.feed(diag("ext_diag", master=MASTER), 0.0)
    frame = slave.poll(0.0)
    assert frame is not None and service_of(frame) is None
    assert slave.state is SlaveState.DATA_EXCHANGE


def test_watchdog_loss_restarts_with_fcb_reset() -> None:
    slave = DpSlave(setup())
    bring_up(slave)
    frame = slave.poll(0.6)  # silent for longer than the 0.5 s watchdog
    assert frame == dps.request(Service.SLAVE_DIAG, SLAVE, MASTER, fcb=True, fcv=False)
    assert slave.take_events() == [
        Restarted(RestartReason.WATCHDOG),
        _changed(SlaveState.DATA_EXCHANGE, SlaveState.WAIT_PRM),
    ]


def test_a_locked_slave_is_never_parametrised() -> None:
    slave = DpSlave(setup())
    for t in range(20):
        frame = slave.poll(float(t))
        if frame is None:
            continue
        assert service_of(frame) is Service.SLAVE_DIAG
        slave.feed(LOCKED_DIAG, float(t))
        assert slave.state is SlaveState.LOCKED
    # Probed once every probe interval, not every cycle.
    assert slave.poll(19.5) is None


def test_retries_then_offline_then_probe() -> None:
    slave = DpSlave(setup(retries=2))
    bring_up(slave)
    first = slave.poll(0.0)
    for _ in range(2):
        assert slave.feed(NoAnswer(), 0.0) == [Failed(FailureKind.TIMEOUT, "no answer")]
        assert slave.poll(0.0) == first  # the same FCB: the slave may resend its answer
    events = slave.feed(NoAnswer(), 0.0)
    assert slave.state is SlaveState.OFFLINE
    assert _changed(SlaveState.DATA_EXCHANGE, SlaveState.OFFLINE) in events
    assert slave.poll(1.0) is None
    assert slave.poll(2.0) == dps.request(Service.SLAVE_DIAG, SLAVE, MASTER, fcb=True, fcv=False)


def test_feed_without_request_is_refused() -> None:
    with pytest.raises(LocalProtocolError, match="no request out"):
        DpSlave(setup()).feed(NoAnswer(), 0.0)


def test_setup_checks() -> None:
    with pytest.raises(LocalProtocolError, match="master address"):
        SlaveSetup(SLAVE, SLAVE, PRM, PPO1_CFG)
    with pytest.raises(LocalProtocolError, match="empty configuration"):
        SlaveSetup(SLAVE, MASTER, PRM, b"")


def _changed(old: SlaveState, new: SlaveState) -> SlaveEvent:
    return StateChanged(old, new)


# ------------------------------------------ every state against every answer

PLACES: dict[str, Callable[[DpSlave], None]] = {}


def _place(name: str) -> Callable[[Callable[[DpSlave], None]], Callable[[DpSlave], None]]:
    def register(fn: Callable[[DpSlave], None]) -> Callable[[DpSlave], None]:
        PLACES[name] = fn
        return fn

    return register


def _feed(slave: DpSlave, *replies: fdl.Frame) -> None:
    for reply in replies:
        assert slave.poll(0.0) is not None
        slave.feed(reply, 0.0)


@_place("offline")
def _offline(slave: DpSlave) -> None:
    pass


@_place("wait_prm")
def _wait_prm(slave: DpSlave) -> None:
    _feed(slave, NOT_READY)


@_place("wait_cfg")
def _wait_cfg(slave: DpSlave) -> None:
    _feed(slave, NOT_READY, ShortAck())


@_place("wait_ready")
def _wait_ready(slave: DpSlave) -> None:
    _feed(slave, NOT_READY, ShortAck(), ShortAck())


@_place("data_exchange")
def _data_exchange(slave: DpSlave) -> None:
    bring_up(slave)


@_place("dx_diag")
def _dx_diag(slave: DpSlave) -> None:
    bring_up(slave)
    _feed(slave, answer(Status.DH, bytes(12)))


@_place("locked")
def _locked(slave: DpSlave) -> None:
    _feed(slave, LOCKED_DIAG)


ANSWERS: dict[str, Callable[[], fdl.Frame | NoAnswer | Garbled]] = {
    "rs": lambda: answer(Status.RS),
    "sc": ShortAck,
    "dl": lambda: answer(Status.DL, bytes(12)),
    "dh": lambda: answer(Status.DH, bytes(12)),
    "garbage": lambda: Garbled("bad FCS"),
    "timeout": NoAnswer,
    "locked_diag": lambda: LOCKED_DIAG,
    "ready_diag": lambda: READY,
    "prm_required": lambda: diag("prm_required", master=MASTER),
    "cfg_fault": lambda: diag("cfg_fault", master=MASTER),
    "foreign": lambda: DataFrame(MASTER, 9, fdl.response_fc(Status.DL), data=bytes(12)),
}

DIAG_PLACES = {"offline", "wait_ready", "dx_diag", "locked"}


@pytest.mark.parametrize("place", sorted(PLACES))
@pytest.mark.parametrize("kind", sorted(ANSWERS))
def test_every_state_against_every_answer(place: str, kind: str) -> None:
    slave = DpSlave(setup(retries=0))
    PLACES[place](slave)
    before = slave.state
    now = 3.0 if place == "locked" else 0.0  # a locked slave is probed after the interval
    request = slave.poll(now)
    assert request is not None
    events = slave.feed(ANSWERS[kind](), now)
    restarts = [e.reason for e in events if isinstance(e, Restarted)]
    next_request = slave.poll(now)
    is_diag_step = place in DIAG_PLACES
    if kind == "rs":
        assert restarts == [RestartReason.RS] and slave.state is SlaveState.WAIT_PRM
        assert next_request == dps.request(Service.SLAVE_DIAG, SLAVE, MASTER, fcb=True, fcv=False)
    elif kind == "timeout":
        assert slave.state is SlaveState.OFFLINE and next_request is None
    elif kind == "locked_diag" and is_diag_step:
        assert slave.state is SlaveState.LOCKED and next_request is None
    elif kind in ("prm_required", "cfg_fault") and place in ("wait_ready", "dx_diag"):
        expected = RestartReason.PRM_REQUIRED if kind == "prm_required" else RestartReason.DIAG
        assert restarts == [expected] and slave.state is SlaveState.WAIT_PRM
    elif any(isinstance(e, Failed) for e in events):
        # retries=0: a useless answer ends this attempt
        assert slave.state in (SlaveState.OFFLINE, SlaveState.WAIT_PRM)
        if before is SlaveState.OFFLINE or before is SlaveState.LOCKED:
            assert slave.state in (SlaveState.OFFLINE, SlaveState.WAIT_PRM)
    else:
        assert not restarts
    if next_request is not None and service_of(next_request) is Service.SET_PRM:
        last = [e for e in events if isinstance(e, DiagnosisRead)]
        assert last and not last[-1].diagnosis.owned_by_other(MASTER)
    if next_request is not None and service_of(next_request) is None:
        assert slave.state is SlaveState.DATA_EXCHANGE


# -------------------------------------------- random walks over every input

STEP_KINDS = sorted(ANSWERS)


@settings(deadline=None, max_examples=300)
@given(
    st.lists(
        st.tuples(st.sampled_from([*STEP_KINDS, "ok"]), st.floats(0.0, 1.0)),
        max_size=60,
    ),
    st.integers(0, 3),
)
def test_random_walk_keeps_the_rules(steps: list[tuple[str, float]], retries: int) -> None:
    slave = DpSlave(setup(retries=retries))
    now = 0.0
    diag_ok = False  # the last diagnosis read allows parametrising
    cfg_acked = prm_acked = False
    previous: DataFrame | None = None
    completed: DataFrame | None = None  # the last request that got a valid answer
    restarted = True
    for kind, dt in steps:
        now += dt
        frame = slave.poll(now)
        events = slave.take_events()
        if any(isinstance(e, Restarted) for e in events):
            restarted = True
        if frame is None:
            assert slave.state in (SlaveState.OFFLINE, SlaveState.LOCKED, SlaveState.WAIT_PRM)
            now += 2.0
            continue
        service = service_of(frame)
        control = frame.control
        if frame == previous and completed is not frame:
            pass  # a repeat: the same bytes, the same FCB
        elif restarted:
            assert (control.fcb, control.fcv) == (True, False), frame
        else:
            assert control.fcv
            assert completed is not None and control.fcb != completed.control.fcb
        if service is Service.SET_PRM:
            assert diag_ok
        if service is None:
            assert slave.state is SlaveState.DATA_EXCHANGE and prm_acked and cfg_acked
        if kind == "ok":
            reply: fdl.Frame | NoAnswer | Garbled
            if service is None:
                reply = answer(Status.DL, bytes(12))
            elif service is Service.SLAVE_DIAG:
                reply = READY if slave.state is SlaveState.WAIT_CFG else NOT_READY
            else:
                reply = ShortAck()
        else:
            reply = ANSWERS[kind]()
        events = slave.feed(reply, now)
        previous = frame
        if any(isinstance(e, Restarted) for e in events) or (
            slave.state
            in (
                SlaveState.OFFLINE,
                SlaveState.LOCKED,
            )
            and not slave.waiting
        ):
            restarted = True
            diag_ok = prm_acked = cfg_acked = False
            completed = None
        if not slave.waiting and not any(isinstance(e, Failed) for e in events):
            completed = frame
            if not any(isinstance(e, Restarted) for e in events) and slave.state not in (
                SlaveState.OFFLINE,
                SlaveState.LOCKED,
            ):
                restarted = False
        for event in events:
            if isinstance(event, DiagnosisRead):
                diag_ok = not event.diagnosis.owned_by_other(MASTER)
        if service is Service.SET_PRM and slave.state is SlaveState.WAIT_CFG:
            prm_acked = True
        if (
            service is Service.CHK_CFG
            and not slave.waiting
            and not any(isinstance(e, Failed | Restarted) for e in events)
        ):
            cfg_acked = True
        if slave.state is SlaveState.LOCKED:
            diag_ok = False


def _probe_times(
    m: DpSlave, answers: Callable[[int], fdl.Frame | NoAnswer], until: float
) -> list[float]:
    """When the master sends its first request after each silence, on a fake clock."""
    sent: list[float] = []
    now, n = 0.0, 0
    while now < until:
        frame = m.poll(now)
        if frame is not None:
            if m.state is not SlaveState.DATA_EXCHANGE and (not sent or now - sent[-1] > 0.5):
                sent.append(now)
            m.feed(answers(n), now)
            n += 1
        now += 0.25
    return sent


def test_an_offline_slave_is_probed_at_capped_exponential_back_off() -> None:
    m = DpSlave(SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG, retries=0, probe_interval=1.0,
                           probe_cap=8.0))  # fmt: skip
    times = _probe_times(m, lambda n: NoAnswer(), 60.0)
    gaps = [round(b - a, 2) for a, b in itertools.pairwise(times)]
    assert gaps[:5] == [1.0, 2.0, 4.0, 8.0, 8.0], gaps
    assert all(g == 8.0 for g in gaps[3:])


def test_a_locked_slave_is_asked_less_and_less_often() -> None:
    m = DpSlave(SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG, probe_interval=1.0, probe_cap=4.0))
    times = _probe_times(m, lambda n: LOCKED_DIAG, 40.0)
    assert m.state is SlaveState.LOCKED
    gaps = [round(b - a, 2) for a, b in itertools.pairwise(times)]
    assert gaps[:3] == [1.0, 2.0, 4.0] and set(gaps[3:]) == {4.0}, gaps


def test_the_back_off_starts_again_after_data_exchange() -> None:
    m = DpSlave(SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG, retries=0, probe_interval=1.0,
                           probe_cap=8.0))  # fmt: skip
    _probe_times(m, lambda n: NoAnswer(), 20.0)  # well into the back-off
    assert m._probe_wait == 8.0
    m._set_state(SlaveState.DATA_EXCHANGE)
    assert m._probe_wait == 1.0
