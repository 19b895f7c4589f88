"""Control and status words, REF/MAV scaling."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pzd import (
    FC_STATUS_BITS,
    MONITORING_CTW,
    PROFIDRIVE_STATUS_BITS,
    Profile,
    control_word,
    percent_to_ref,
    ref_to_percent,
    status_bits,
    status_word,
    takes_control,
)


def test_monitoring_control_word_never_takes_control() -> None:
    assert not takes_control(MONITORING_CTW)
    assert takes_control(control_word(Profile.FC, data_valid=True))
    assert takes_control(control_word(Profile.PROFIDRIVE, control_by_plc=True))
    assert not takes_control(control_word(Profile.FC, ramp_stop=True, jog=True))


def test_fc_status_word_example() -> None:
    # protocol.md 7: STW 0x0607 = control ready, drive ready, enabled, at reference, bus control
    bits = status_bits(0x0607, Profile.FC)
    on = {name for name, value in bits.items() if value}
    assert on == {
        "control_ready",
        "drive_ready",
        "enabled",
        "bus_control",
        "frequency_within_limit",
    }


def test_status_bit_names_from_protocol_md() -> None:
    assert FC_STATUS_BITS[3] == "trip" and FC_STATUS_BITS[11] == "running"
    assert (
        PROFIDRIVE_STATUS_BITS[3] == "fault" and PROFIDRIVE_STATUS_BITS[10] == "reference_reached"
    )


@given(word=st.integers(0, 0xFFFF), profile=st.sampled_from(list(Profile)))
def test_status_word_round_trip(word: int, profile: Profile) -> None:
    bits = status_bits(word, profile)
    named = sum(
        1 << b for b in (FC_STATUS_BITS if profile is Profile.FC else PROFIDRIVE_STATUS_BITS)
    )
    assert status_word(profile, **bits) == word & named


def test_unknown_bit_name() -> None:
    with pytest.raises(LocalProtocolError):
        status_word(Profile.FC, nonsense=True)


@pytest.mark.parametrize(
    ("raw", "percent"), [(0x4000, 100.0), (0x2000, 50.0), (0x0000, 0.0), (0xC000, -100.0)]
)
def test_ref_scaling(raw: int, percent: float) -> None:
    assert ref_to_percent(raw) == percent
    assert percent_to_ref(percent) == raw


def test_ref_range() -> None:
    with pytest.raises(LocalProtocolError):
        ref_to_percent(0x10000)
    with pytest.raises(LocalProtocolError):
        percent_to_ref(250.0)
