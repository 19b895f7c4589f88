"""DP-V0 services (pkwbus.protocol.profibus.dp.services): the requests a master cannot
send, and the Set_Prm and diagnosis bytes a slave must not receive, each with its reason."""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.services import Diagnosis, Parameters, Service

# The Set_Prm data of the captured Festo start-up (pyprofibus issue 19): station
# status B8 (lock, sync, freeze, watchdog on), WD factors 1E 01, min TSDR 0,
# ident 0A35, group 01, 7 user parameter bytes.
FESTO_SET_PRM = bytes.fromhex("B8 1E 01 00 0A 35 01 00 00 00 82 00 00 00")


@pytest.mark.parametrize(
    ("slave", "master", "why"),
    [
        (126, 2, "slave address 126 is outside 0-125"),
        (-1, 2, "slave address -1 is outside 0-125"),
        (8, 126, "master address 126 is outside 0-125"),
        (8, 127, "master address 127 is outside 0-125"),  # 127: the broadcast address
    ],
)
def test_a_request_to_or_from_no_station(slave: int, master: int, why: str) -> None:
    with pytest.raises(LocalProtocolError, match=why):
        dps.request(Service.SLAVE_DIAG, slave, master, fcb=True, fcv=False)


def test_the_highest_station_addresses_are_usable() -> None:
    frame = dps.request(None, 125, 0, b"\x00", fcb=False, fcv=True)
    assert fdl.decode(fdl.encode(frame)) == frame


def test_a_diagnosis_flag_asked_by_its_name() -> None:
    diag = dps.decode_diagnosis(bytes.fromhex("02 05 00 FF 0A 35"))  # Festo, not ready
    assert diag.has("not_ready") and diag.has("prm_required")
    assert not diag.has("cfg_fault")


def test_a_diagnosis_the_slave_side_cannot_send() -> None:
    with pytest.raises(LocalProtocolError, match="no diagnosis flag named 'not_redy'"):
        dps.encode_diagnosis(Diagnosis(frozenset({"not_redy"}), None, 0x0A35))
    with pytest.raises(LocalProtocolError, match="master address 126 is outside 0-125"):
        dps.encode_diagnosis(Diagnosis(frozenset(), 126, 0x0A35))
    with pytest.raises(LocalProtocolError, match="ident number 65536 is not 16 bits"):
        dps.encode_diagnosis(Diagnosis(frozenset(), 2, 0x10000))


def test_set_prm_without_the_watchdog() -> None:
    prm = Parameters(0x0A35, lock=True)
    assert prm.watchdog_seconds is None
    data = prm.encode()
    assert data[0] == 0x80  # lock only: WD_On (bit 3) clear
    assert dps.decode_parameters(data) == prm


@pytest.mark.parametrize(
    ("prm", "why"),
    [
        (Parameters(1, watchdog=(0, 1)), "watchdog factors 0, 1 are outside 1-255"),
        (Parameters(1, watchdog=(1, 256)), "watchdog factors 1, 256 are outside 1-255"),
        (Parameters(1, group=256), "group 256 is not a byte"),
        (Parameters(1, min_tsdr=-1), "min TSDR -1 is outside 0-255 bit times"),
    ],
)
def test_set_prm_a_master_cannot_send(prm: Parameters, why: str) -> None:
    with pytest.raises(LocalProtocolError, match=why):
        prm.encode()


@pytest.mark.parametrize(
    ("data", "why"),
    [
        (FESTO_SET_PRM[:6], "Set_Prm of 6 bytes \\(at least 7\\)"),
        (b"", "Set_Prm of 0 bytes"),
        # watchdog on, but factor 1 is 0: no time the slave could watch
        (bytes.fromhex("B8 00 01 00 0A 35 01"), "Set_Prm with a watchdog factor of 0"),
        (bytes.fromhex("08 1E 00 00 0A 35 01"), "Set_Prm with a watchdog factor of 0"),
    ],
)
def test_set_prm_a_slave_cannot_take(data: bytes, why: str) -> None:
    with pytest.raises(RemoteProtocolError, match=why):
        dps.decode_parameters(data)


def test_a_watchdog_factor_of_0_is_nothing_when_the_watchdog_is_off() -> None:
    prm = dps.decode_parameters(bytes.fromhex("80 00 00 00 0A 35 01"))
    assert prm.watchdog is None and prm.watchdog_seconds is None


def test_an_empty_slot_is_a_module_of_its_own() -> None:
    # MICROMASTER 4: an empty slot 00 before PPO 3's F1.
    empty, ppo3 = dps.parse_cfg(b"\x00\xf1")
    assert empty.empty and (empty.inputs, empty.outputs) == (0, 0)
    assert not ppo3.empty


def test_a_configuration_of_more_than_244_bytes_is_refused() -> None:
    # 5F: 16 input words (32 bytes); eight of them are 256 bytes, beyond the 244 a
    # DP slave exchanges.
    with pytest.raises(LocalProtocolError, match="configuration of 256 input, 0 output bytes"):
        dps.check_cfg(b"\x5f" * 8)
    with pytest.raises(LocalProtocolError, match="configuration of 0 input, 256 output bytes"):
        dps.check_cfg(b"\x6f" * 8)
    dps.check_cfg(b"\x5f" * 7 + b"\x53")  # 224 + 8 = 232: fits


def test_global_control_clear_refusals_and_group() -> None:
    with pytest.raises(LocalProtocolError, match="master address 126 is outside 0-125"):
        dps.global_control_clear(126)
    with pytest.raises(LocalProtocolError, match="group select 256 is not a byte"):
        dps.global_control_clear(2, 256)
    frame = dps.global_control_clear(2, 0x05)
    assert frame.data == bytes((0x02, 0x05))  # Clear_Data, then the group select
    assert (frame.da, frame.dsap) == (127, 58)
