"""A DP-V1 slave's record transfer inside the master's state machine
(pkwbus.protocol.profibus.dp.slave with dpv1.transfer): the MSAC_C1 write and reads
between the Data_Exchanges, every answer the slave may give them, and what ends them;
the setup's checks (dp.slave_model)."""

from __future__ import annotations

import itertools
import re

import pytest

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.slave import (
    DpSlave,
    Failed,
    FailureKind,
    Inputs,
    NoAnswer,
    Restarted,
    RestartReason,
    SlaveSetup,
    SlaveState,
    StateChanged,
    TransferEnded,
)
from pkwbus.protocol.profibus.dpv1.msac import C1_SAP, Dpv1Setup, read_request
from pkwbus.protocol.profibus.dpv1.transfer import RecordFailed, RecordRead
from pkwbus.protocol.profibus.fdl import DataFrame, ShortAck, Status
from tests.protocol.profibus.test_dp import (
    MASTER,
    PPO1_CFG,
    PRM,
    SLAVE,
    answer,
    bring_up,
    diag,
    service_of,
)

# ABB FPBA-01 PROFIBUS DP adapter module user's manual, "Communication protocol",
# example 3: the DP-V1 write of a PROFIdrive request (read parameter 918) to slot 1,
# index 47, and the read response that carries the drive's answer.
ABB_WRITE_918 = bytes.fromhex("5F 01 2F 0A 09 01 01 01 10 00 03 96 00 00")
ABB_READ_RESPONSE_918 = bytes.fromhex("5E 01 2F 08 09 01 01 01 42 01 00 03")
REQUEST_918 = ABB_WRITE_918[4:]
# The negative read answer of a slave whose response is not there yet: "state conflict".
NOT_READY = bytes.fromhex("DE 80 B5 00")


def dpv1_setup(
    retries: int = 1, timeout: float = 0.5, read_write: bool = True, **kw: object
) -> SlaveSetup:
    dpv1 = Dpv1Setup(response_timeout=timeout, read_write=read_write)
    return SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG, retries=retries, dpv1=dpv1, **kw)  # type: ignore[arg-type]


def exchanging(**kw: object) -> DpSlave:
    slave = DpSlave(dpv1_setup(**kw))  # type: ignore[arg-type]
    bring_up(slave)
    return slave


def c1(data: bytes, status: Status = Status.DL) -> DataFrame:
    """The slave's answer from its MSAC_C1 service access point."""
    return DataFrame(MASTER, SLAVE, fdl.response_fc(status), C1_SAP, C1_SAP, data)


def exchange(slave: DpSlave, now: float, status: Status = Status.DL) -> DataFrame:
    frame = slave.poll(now)
    assert frame is not None and service_of(frame) is None  # a Data_Exchange
    assert slave.feed(answer(status, bytes(12)), now) == [Inputs(bytes(12), status is Status.DH)]
    return frame


def acyclic(slave: DpSlave) -> DataFrame:
    frame = slave.poll_acyclic()
    assert frame is not None
    return frame


def test_the_abb_read_of_918_travels_between_the_data_exchanges() -> None:
    slave = exchanging()
    slave.start_transfer(1, 47, REQUEST_918, 0.0)
    sent = [exchange(slave, 0.0)]
    write = acyclic(slave)
    sent.append(write)
    # SRD to SAP 51 from SAP 51, carrying the write byte for byte
    assert (write.da, write.sa, write.dsap, write.ssap) == (SLAVE, MASTER, 51, 51)
    assert write.control.function is fdl.Function.SRD_HIGH
    assert write.data == ABB_WRITE_918
    assert slave.feed(c1(ABB_WRITE_918[:4]), 0.01) == []  # the write's echo: 5F 01 2F 0A
    reads = 0
    for now, reply in (
        (0.05, c1(NOT_READY)),  # state conflict
        (0.10, ShortAck()),  # a short acknowledgement
        (0.15, c1(b"", Status.NR)),  # an answer without data
    ):
        sent.append(exchange(slave, now))
        read = acyclic(slave)
        sent.append(read)
        assert read.data == read_request(1, 47, 240) == bytes.fromhex("5E 01 2F F0")
        assert slave.feed(reply, now) == []  # not ready: read again
        reads += 1
    sent.append(exchange(slave, 0.2))
    sent.append(acyclic(slave))
    events = slave.feed(c1(ABB_READ_RESPONSE_918), 0.2)
    assert events == [TransferEnded(RecordRead(ABB_READ_RESPONSE_918[4:], reads + 1))]
    assert slave.transfer is None and slave.poll_acyclic() is None
    assert slave.state is SlaveState.DATA_EXCHANGE
    # Every new request to the slave toggles the FCB, the MSAC_C1 ones included.
    fcbs = [frame.control.fcb for frame in sent]
    assert all(a != b for a, b in itertools.pairwise(fcbs))
    assert all(frame.control.fcv for frame in sent)


def test_an_unanswered_transfer_request_goes_again_unchanged() -> None:
    slave = exchanging(retries=2)
    slave.start_transfer(1, 47, REQUEST_918, 0.0)
    exchange(slave, 0.0)
    assert slave.repeat_acyclic() is None  # nothing of the transfer's out
    write = acyclic(slave)
    assert slave.poll_acyclic() is None  # one request out at a time
    assert slave.poll(0.0) == write  # and it holds up the cycle
    assert slave.feed(NoAnswer(), 0.01) == [Failed(FailureKind.TIMEOUT, "no answer")]
    assert slave.repeat_acyclic() == write  # the same bytes, the same FCB
    foreign = DataFrame(MASTER, 9, fdl.response_fc(Status.DL), C1_SAP, C1_SAP, ABB_WRITE_918[:4])
    events = slave.feed(foreign, 0.02)
    assert len(events) == 1 and isinstance(events[0], Failed)
    assert events[0].kind is FailureKind.UNEXPECTED
    assert "is not this slave's answer" in events[0].detail
    assert slave.repeat_acyclic() == write
    # The retries are spent: the slave is offline, and the transfer over with it.
    events = slave.feed(NoAnswer(), 0.03)
    assert TransferEnded(RecordFailed("the slave left data exchange")) in events
    assert StateChanged(SlaveState.DATA_EXCHANGE, SlaveState.OFFLINE) in events
    assert slave.transfer is None and slave.repeat_acyclic() is None


@pytest.mark.parametrize(
    ("reply", "why"),
    [
        # RS: the slave has no SAP 51 active, it does not run DP-V1
        (c1(b"", Status.RS), "no MSAC_C1 service access point \\(51\\) active"),
        (answer(Status.RS), "no MSAC_C1 service access point"),
        # an answer from another SAP, or with another status, is no MSAC_C1 answer
        (answer(Status.DL, ABB_WRITE_918[:4]), "answers an MSAC_C1 request"),
        (c1(ABB_WRITE_918[:4], Status.UE), "answers an MSAC_C1 request"),
        (c1(ABB_WRITE_918[:4], Status.RR), "answers an MSAC_C1 request"),
        # an MSAC_C1 answer that is not the write's
        (c1(bytes.fromhex("5F 00 2F 0A")), "an answer for slot 0 index 47, asked slot 1"),
        (c1(bytes.fromhex("5E 01 2F 00")), "MSAC_C1 function 0x5e answers 0x5f"),
        # a negative answer other than "state conflict": Access, Invalid Index
        (c1(bytes.fromhex("DF 80 B0 00")), "DP-V1 write refused: Access, Invalid Index"),
    ],
)
def test_an_answer_that_ends_the_transfer_says_why(reply: DataFrame, why: str) -> None:
    slave = exchanging()
    slave.start_transfer(1, 47, REQUEST_918, 0.0)
    exchange(slave, 0.0)
    acyclic(slave)
    events = slave.feed(reply, 0.01)
    assert len(events) == 1 and isinstance(events[0], TransferEnded)
    end = events[0].end
    assert isinstance(end, RecordFailed) and not end.timed_out
    assert re.search(why, end.why), end.why
    # The slave answered: it stays in data exchange, and the cycle goes on.
    assert slave.state is SlaveState.DATA_EXCHANGE and slave.transfer is None
    exchange(slave, 0.02)


def test_a_transfer_the_slave_keeps_from_going_on_ends_at_its_timeout() -> None:
    slave = exchanging(timeout=0.2)
    slave.start_transfer(1, 47, REQUEST_918, 0.0)
    exchange(slave, 0.1, Status.DH)  # a diagnosis waits: it is fetched first
    assert slave.poll_acyclic() is None
    frame = slave.poll(0.3)  # past the transfer's 0.2 s, within the 0.5 s watchdog
    assert frame is not None
    assert slave.take_events() == [
        TransferEnded(
            RecordFailed(
                "no answer to the record transfer within the slave's response timeout (0.2 s)",
                timed_out=True,
            )
        )
    ]
    assert slave.transfer is None


def test_a_transfer_is_only_started_on_a_dpv1_slave_in_data_exchange() -> None:
    plain = DpSlave(SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG))
    bring_up(plain)
    with pytest.raises(LocalProtocolError, match="slave 8 is no DP-V1 slave with records"):
        plain.start_transfer(0, 47, REQUEST_918, 0.0)
    no_records = exchanging(read_write=False)  # GSD: C1_Read_Write_supp = 0
    with pytest.raises(LocalProtocolError, match="no DP-V1 slave with records"):
        no_records.start_transfer(0, 47, REQUEST_918, 0.0)
    starting = DpSlave(dpv1_setup())
    with pytest.raises(LocalProtocolError, match="slave 8 is not in data exchange"):
        starting.start_transfer(0, 47, REQUEST_918, 0.0)
    busy = exchanging()
    busy.start_transfer(0, 47, REQUEST_918, 0.0)
    with pytest.raises(LocalProtocolError, match="slave 8 has a transfer in progress"):
        busy.start_transfer(0, 47, REQUEST_918, 0.0)


def test_a_dpv1_slave_is_parametrised_with_dpv1_on() -> None:
    # Set_Prm: 7 standard bytes, then DPV1_Status_1..3, bit 7 of the first set.
    data = dpv1_setup().prm_data()
    assert data[:7] == PRM.encode()[:7]
    assert data[7:] == bytes((0x80, 0, 0))
    assert SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG).prm_data() == PRM.encode()


# ---------------------------------------------------- the cyclic side, refusals


@pytest.mark.parametrize("status", [Status.UE, Status.RR, Status.RDL, Status.RDH])
def test_a_refusing_answer_to_a_data_exchange_is_a_failure(status: Status) -> None:
    slave = DpSlave(SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG, retries=1))
    bring_up(slave)
    request = slave.poll(0.0)
    events = slave.feed(answer(status, bytes(12)), 0.0)
    assert len(events) == 1 and isinstance(events[0], Failed)
    assert events[0].kind is FailureKind.REFUSED
    assert slave.poll(0.0) == request  # repeated, the same FCB
    assert slave.state is SlaveState.DATA_EXCHANGE


def test_a_slave_not_ready_in_data_exchange_is_started_again() -> None:
    slave = DpSlave(SlaveSetup(SLAVE, MASTER, PRM, PPO1_CFG, probe_interval=2.0))
    bring_up(slave)
    exchange(slave, 0.0, Status.DH)
    request = slave.poll(0.0)
    assert request is not None and service_of(request) is not None  # Slave_Diag
    events = slave.feed(diag("not_ready", master=MASTER), 0.0)
    assert Restarted(RestartReason.DIAG) in events
    assert slave.state is SlaveState.WAIT_PRM
    assert slave.poll(1.0) is None  # after the probe interval, not at once
    assert slave.poll(2.0) is not None


@pytest.mark.parametrize(
    ("kw", "why"),
    [
        ({"address": 126}, "slave address 126 is outside 0-125"),
        ({"address": -1}, "slave address -1 is outside 0-125"),
        ({"master": 126}, "master address 126 is not usable"),
        ({"retries": 9}, "retry limit 9 is outside 0-8"),
        ({"probe_interval": -1.0}, "probe interval below 0, or above its cap"),
        ({"probe_interval": 5.0, "probe_cap": 4.0}, "probe interval below 0, or above its cap"),
    ],
)
def test_a_setup_the_master_cannot_run_is_refused(kw: dict[str, object], why: str) -> None:
    args: dict[str, object] = {
        "address": SLAVE,
        "master": MASTER,
        "parameters": PRM,
        "cfg": PPO1_CFG,
        **kw,
    }
    with pytest.raises(LocalProtocolError, match=why):
        SlaveSetup(**args)  # type: ignore[arg-type]
