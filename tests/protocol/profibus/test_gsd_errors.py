"""GSD files (pkwbus.protocol.profibus.gsd): user parameter definitions and settings a
slave cannot be parametrised with, each refused naming its line; what a file that
names no baud rate says; a module known as a PPO by its name alone."""

from __future__ import annotations

import pytest

from pkwbus.protocol.profibus import gsd
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.dp.ppo import ppo_type
from pkwbus.protocol.profibus.gsd import GsdError

HEAD = "#Profibus_DP\nIdent_Number = 0x0001\n"  # lines 1 and 2


def read(text: str) -> gsd.Gsd:
    return gsd.parse(HEAD + text)


def definition(type_line: str) -> str:
    """ExtUserPrmData 1 on lines 3-5 with ``type_line``, used at byte 0 on line 6."""
    return (
        f'ExtUserPrmData = 1 "Mode"\n{type_line}\nEndExtUserPrmData\nExt_User_Prm_Data_Ref(0) = 1\n'
    )


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        # Set_Prm has 237 user parameter bytes: offsets 0-236
        ("Ext_User_Prm_Data_Const(237) = 1\n", 3, "byte offset 237 is outside 0-236"),
        ("Ext_User_Prm_Data_Ref(300) = 1\n", 3, "byte offset 300 is outside 0-236"),
        (
            'ExtUserPrmData = 1 "Mode"\nPrm_Text_Ref = 1\nEndExtUserPrmData\n'
            "Ext_User_Prm_Data_Ref(0) = 1\n",
            6,
            "ExtUserPrmData 1 \\(line 3\\) ExtUserPrmData 1 has no data type line",
        ),
        (definition("Unsigned8"), 6, "cannot read the data type line 'Unsigned8'"),
        (definition("Bit 1 0-1"), 6, "\\(line 4\\) Bit needs a bit number"),
        (definition("BitArea 1 0-3"), 6, "BitArea needs a bit number"),
        (definition("Bit(0) 2 0-1"), 6, "default 2 does not fit bits 0-0"),
        (definition("BitArea(4-5) 4 0-3"), 6, "default 4 does not fit bits 4-5"),
        ("DPV1_Slave = 1\nC1_Response_Timeout = 0\n", 4, "C1_Response_Timeout 0 is outside"),
        ("DPV1_Slave = 1\nC1_Response_Timeout = 65536\n", 4, "outside 1-65535"),
        # 238 bytes of User_Prm_Data: more than Set_Prm carries
        ("User_Prm_Data = " + ",".join(["0x01"] * 238) + "\n", 0, "238 user parameter bytes"),
    ],
)
def test_errors_name_the_line(text: str, line: int, message: str) -> None:
    with pytest.raises(GsdError, match=message) as caught:
        read(text)
    assert caught.value.line == line


def test_a_data_type_line_without_allowed_values_allows_any() -> None:
    found = read(definition("Unsigned8 7"))
    assert found.user_prm == b"\x07"
    prm = found.prm_definitions[1]
    assert (prm.default, prm.allowed, prm.is_range) == (7, None, False)


def test_a_module_whose_parameter_length_cannot_be_is_read_past_and_told() -> None:
    found = read('Module = "A" 0xF1\nExt_Module_Prm_Data_Len = 238\nEndModule\n')
    assert found.modules == ()
    assert found.warnings == (
        "line 4: Ext_Module_Prm_Data_Len 238 is outside 0-237: module read past",
    )


def test_an_info_text_without_quotes_is_taken_as_it_stands() -> None:
    (module,) = read('Module = "A" 0xF1\nInfo_Text = plain words\nEndModule\n').modules
    assert module.info == "plain words"


def test_a_continuation_at_the_end_of_the_file_ends_its_statement() -> None:
    assert read("User_Prm_Data = 0x01,0x02 \\").user_prm == b"\x01\x02"


def test_a_file_that_names_no_rate_says_nothing_of_any() -> None:
    found = read("")
    assert found.supports(9600) is None
    assert found.rates_text() == "none"
    rated = read("9.6_supp = 1\n19.2_supp = 1\n")
    assert rated.supports(9600) is True and rated.supports(93750) is False
    assert rated.rates_text() == "9600, 19200"


def test_a_module_named_ppo_n_is_that_ppo_whatever_its_consistency() -> None:
    # PPO 2 with consistency over each word (0x73, 0x75) instead of the whole length
    # (0xF3, 0xF5): the same 20 bytes each way, told by its name.
    (module,) = read('Module = "PPO 2 (word consistent)" 0x73,0x75\nEndModule\n').modules
    assert module.cfg != ppo_type(2).cfg
    assert gsd.ppo_of(module) == 2
    assert dp_services.io_lengths(module.cfg) == (20, 20)
    found = read('Module = "PPO 9" 0x73,0x75\nEndModule\n')
    assert gsd.ppo_of(found.modules[0]) is None  # no PPO 9
