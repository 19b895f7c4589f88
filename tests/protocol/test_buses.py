"""Each protocol's addresses, PKW lengths and dialects, asked in one place."""

from __future__ import annotations

import pytest

from pkwbus.master.target import DriveTarget
from pkwbus.notation import limits
from pkwbus.protocol import buses
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.serial.telegram import FcAddressFormat, fc_adr, uss_adr


@pytest.mark.parametrize(
    ("protocol", "fmt"),
    [
        (Bus.FC, FcAddressFormat.RANGE_1_126),
        (Bus.FC, FcAddressFormat.RANGE_1_31),
        (Bus.USS, FcAddressFormat.RANGE_1_126),
    ],
)
def test_the_range_is_what_the_adr_byte_encodes(protocol: Bus, fmt: FcAddressFormat) -> None:
    low, high = buses.address_range(protocol, fmt)
    encode = (lambda a: fc_adr(a, fmt)) if protocol is Bus.FC else uss_adr
    for address in (low, high):
        encode(address)
        DriveTarget.create(protocol, address, fc_format=fmt)
    with pytest.raises(LocalProtocolError):
        DriveTarget.create(protocol, high + 1, fc_format=fmt)
    with pytest.raises(LocalProtocolError):
        DriveTarget.create(protocol, low - 1, fc_format=fmt)


def test_every_protocol_speaks_its_own_dialects_only() -> None:
    for protocol, names in buses.DIALECTS_BY_PROTOCOL.items():
        assert buses.default_dialect(protocol) == names[0]
        for name in names:
            DriveTarget.create(protocol, 1, dialect_name=name)
        for other in set(buses.DIALECTS_BY_PROTOCOL) - {protocol}:
            for name in set(buses.DIALECTS_BY_PROTOCOL[other]) - set(names):  # PKW over DP: USS's
                with pytest.raises(LocalProtocolError, match="is not for protocol"):
                    DriveTarget.create(protocol, 1, dialect_name=name)


def test_pkw_lengths() -> None:
    assert [buses.pkw_words(n) for n in (0, 3, 4, 127, "variable")] == [0, 3, 4, None, None]
    assert buses.pkw_words("127", text=True) is None
    assert buses.pkw_words("3", text=True) == 3
    for bad in (5, True, "4", "many", 3.0):
        with pytest.raises(ValueError, match="is not a PKW length"):
            buses.pkw_words(bad)


def test_address_lists() -> None:
    assert limits.parse_addresses("5,1-3, 2", 0, 126) == [1, 2, 3, 5]
    assert limits.parse_addresses("", 0, 126) == []
    for bad, words in (
        ("3-1", "runs backwards"),
        ("1-99999999999", "outside 0-126"),
        ("127", "outside 0-126"),
        ("a", "is not an address"),
        ("1-", "is not an address"),
    ):
        with pytest.raises(ValueError, match=words):
            limits.parse_addresses(bad, 0, 126)


def test_a_masters_pkw_length_may_also_be_learned() -> None:
    assert buses.pkw_setting("auto") == "auto"
    assert [buses.pkw_setting(n) for n in (0, 3, 4, 127, "variable")] == [0, 3, 4, None, None]
    assert buses.pkw_setting("4", text=True) == 4
    for bad in (5, "Auto", "4", None):
        with pytest.raises(ValueError, match=r"is not a PKW length: use auto, 0, 3, 4 or variable"):
            buses.pkw_setting(bad)
