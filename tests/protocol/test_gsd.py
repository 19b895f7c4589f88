"""GSD text: ident, user parameters with their defaults, modules, MaxTsdr; errors with line numbers.

The GSD texts here are written for the tests (no vendor file is shipped).
"""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkwbus.protocol import dp_services, gsd
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.gsd import GsdError

DRIVE = """\
;  A made-up drive for the tests
#Profibus_DP
GSD_Revision        = 3
Vendor_Name         = "Test Drives"   ; a comment after a value
Model_Name          = "TD 100; with semicolon"
IDENT_NUMBER        = 0x0402
MaxTsdr_9.6         = 60
maxtsdr_19.2        = 60
MaxTsdr_93.75       = 60
MaxTsdr_1.5M        = 150
Max_User_Prm_Data_Len = 5
User_Prm_Data_Len   = 5
;
PrmText = 1
Text(0) = "off"
Text(1) = "on"
EndPrmText
;
ExtUserPrmData = 1 "Fault reaction"
Unsigned8 2 0-5
Prm_Text_Ref = 1
EndExtUserPrmData
ExtUserPrmData = 2 "Diag on"
Bit(3) 1 0-1
EndExtUserPrmData
ExtUserPrmData = 3 "Mode"
BitArea(4-6) 5 0-7
EndExtUserPrmData
ExtUserPrmData = 4 "Timeout"
Unsigned16 0x1234 0-65535
EndExtUserPrmData
;
Ext_User_Prm_Data_Const(0) = 0x00, 0x80, \\
                             0x00
Ext_User_Prm_Data_Ref(1) = 2
Ext_User_Prm_Data_Ref(1) = 3
Ext_User_Prm_Data_Ref(2) = 1
Ext_User_Prm_Data_Ref(3) = 4
;
Module = "PPO 1" 0xF3,0xF1
1
EndModule
Module = "PPO 3" 0x00, \\
   0xF1
3
EndModule
module = "PPO 5" 0xF3,0xF9
EndModule
"""


def test_a_complete_file() -> None:
    parsed = gsd.parse(DRIVE)
    assert parsed.ident == 0x0402
    assert parsed.vendor == "Test Drives"
    assert parsed.model == "TD 100; with semicolon"
    assert parsed.max_tsdr == {9_600: 60, 19_200: 60, 93_750: 60, 1_500_000: 150}
    # byte 1: const 0x80 | bit 3 (1) | bits 4-6 (5) = 0x80 | 0x08 | 0x50
    assert parsed.user_prm == bytes((0x00, 0xD8, 0x02, 0x12, 0x34))
    assert [(m.name, m.cfg, m.reference) for m in parsed.modules] == [
        ("PPO 1", b"\xf3\xf1", 1),
        ("PPO 3", b"\x00\xf1", 3),
        ("PPO 5", b"\xf3\xf9", None),
    ]
    assert parsed.module("ppo 3").cfg == b"\x00\xf1"
    for module in parsed.modules:
        dp_services.check_cfg(module.cfg)


def test_plain_user_prm_data_and_crlf() -> None:
    text = (
        "#Profibus_DP\r\nIdent_Number = 0x80B5\r\nUser_Prm_Data_Len = 4\r\nUser_Prm_Data = 0,1\r\n"
    )
    parsed = gsd.parse(text)
    assert parsed.ident == 0x80B5
    assert parsed.user_prm == b"\x00\x01\x00\x00"
    assert parsed.modules == ()


def test_module_parameters() -> None:
    text = """#Profibus_DP
Ident_Number = 1
ExtUserPrmData = 7 "Gain"
Signed8 -2 -10-10
EndExtUserPrmData
Module = "Analog" 0x13
Ext_User_Prm_Data_Const(0) = 0x05
Ext_User_Prm_Data_Ref(1) = 7
EndModule
"""
    parsed = gsd.parse(text)
    module = parsed.module("Analog")
    assert module.user_prm == b"\x05\xfe"
    assert parsed.prm_for([module]) == parsed.user_prm + b"\x05\xfe"


def test_unknown_module_name() -> None:
    with pytest.raises(LocalProtocolError, match=r"no module 'PPO 9'.*'PPO 1'"):
        gsd.parse(DRIVE).module("PPO 9")


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("", 0, "no #Profibus_DP"),
        ("Ident_Number = 1\n", 1, "no #Profibus_DP"),
        ("#Profibus_DP\nVendor_Name = 'x'\n", 0, "no Ident_Number"),
        ("#Profibus_DP\nIdent_Number = 0xZZ\n", 2, "not a number"),
        ("#Profibus_DP\nIdent_Number = 0x10000\n", 2, "not 16 bits"),
        ("#Profibus_DP\nIdent_Number = 1\nUser_Prm_Data_Len = 999999999\n", 3, "outside 0-237"),
        ("#Profibus_DP\nIdent_Number = 1\nthis is not a line\n", 3, "cannot read"),
        ('#Profibus_DP\nIdent_Number = 1\nModule = "A" 0xF1\n', 3, "without EndModule"),
        ('#Profibus_DP\nIdent_Number = 1\nModule = "A"\nEndModule\n', 3, "no configuration"),
        ('#Profibus_DP\nIdent_Number = 1\nModule = "A" 0x1F1\nEndModule\n', 3, "not a byte"),
        ("#Profibus_DP\nIdent_Number = 1\nEndModule\n", 3, "EndModule without"),
        ("#Profibus_DP\nIdent_Number = 1\nModule = A 0xF1\nEndModule\n", 3, "quoted name"),
        ("#Profibus_DP\nIdent_Number = 1\nExt_User_Prm_Data_Ref(0) = 9\n", 3, "undefined"),
        ("#Profibus_DP\nIdent_Number = 1\nExt_User_Prm_Data_Const = 1\n", 3, "offset"),
        ('#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\n', 3, "without its End"),
        (
            '#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\nFloat32 1 0-2\n'
            "EndExtUserPrmData\n",
            4,
            "unknown data type",
        ),
        (
            '#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\nUnsigned8 300 0-2\n'
            "EndExtUserPrmData\n",
            4,
            "does not fit",
        ),
        (
            '#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\nBit(9) 1 0-1\n'
            "EndExtUserPrmData\n",
            4,
            "outside 0-7",
        ),
    ],
)
def test_errors_name_the_line(text: str, line: int, message: str) -> None:
    with pytest.raises(GsdError, match=message) as caught:
        gsd.parse(text)
    assert caught.value.line == line
    if line:
        assert str(caught.value).startswith(f"GSD line {line}:")


@settings(deadline=None)
@given(st.text(max_size=400))
def test_any_text_is_read_or_refused_clearly(text: str) -> None:
    with contextlib.suppress(GsdError):
        gsd.parse("#Profibus_DP\n" + text)


@settings(deadline=None)
@given(st.binary(max_size=8), st.sampled_from(["\n", "\r\n"]), st.booleans())
def test_user_prm_data_round_trip(data: bytes, newline: str, continued: bool) -> None:
    items = [f"0x{b:02X}" for b in data]
    sep = ", \\" + newline + "  " if continued else ","
    body = sep.join(items)
    text = newline.join(
        ["#Profibus_DP", "ident_number = 7", f"User_Prm_Data_Len = {len(data)}"]
        + ([f"User_Prm_Data = {body}"] if data else [])
    )
    assert gsd.parse(text + newline).user_prm == data


def test_a_dpv1_slave_and_its_class_1_services() -> None:
    assert gsd.parse(DRIVE).dpv1 is None  # no DPV1_Slave: a DP-V0 slave
    text = DRIVE + "DPV1_Slave = 1\nC1_Read_Write_supp = 1\nC1_Max_Data_Len = 200\n"
    text += "C1_Response_Timeout = 100\n"
    setup = gsd.parse(text).dpv1
    assert setup is not None
    assert (setup.max_data, setup.response_timeout, setup.read_write) == (200, 1.0, True)
    bare = gsd.parse(DRIVE + "DPV1_Slave = 1\n").dpv1
    assert bare is not None and (bare.max_data, bare.read_write) == (240, False)
    with pytest.raises(gsd.GsdError, match="C1_Max_Data_Len 241"):
        gsd.parse(DRIVE + "DPV1_Slave = 1\nC1_Max_Data_Len = 241\n")
