"""GSD files as vendors write them: the whole syntax of the PROFIBUS GSD specification.

The files and texts here are written for the tests, in the shape of vendor
files (no vendor file is shipped): ``gsd_files/mm4_like.gse`` has the
structure of a Siemens MICROMASTER 4 file (Latin-1, a banner before the
header, DP-V1 keys, PPO modules ``0xF3, 0xF1`` and ``0x00, 0xF1``, module
reference numbers on lines of their own, continuation lines). Set
``PKWBUS_GSD_DIR`` to a folder of GSD files (a vendor catalog) to read every
one of them too.
"""

from __future__ import annotations

import contextlib
import os
import re
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus import gsd
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.dp.ppo import PPO_TYPES
from pkwbus.protocol.profibus.gsd import GsdError

FILES = Path(__file__).parent / "gsd_files"
MM4 = FILES / "mm4_like.gse"
EXTENSIONS = (".gsd", ".gse", ".gsg", ".gsf", ".gsi", ".gss")
HEAD = "#Profibus_DP\nIdent_Number = 0x0001\n"


def mm4_bytes() -> bytes:
    return MM4.read_bytes()


def read(text: str) -> gsd.Gsd:
    return gsd.parse(HEAD + text)


# ------------------------------------------------------------- a whole file


def test_the_mm4_like_file_is_read_whole() -> None:
    data = mm4_bytes()
    assert b"\xfc" in data  # Latin-1: "ü" is one byte
    found = gsd.parse(gsd.decode(data))
    assert (found.ident, found.vendor, found.model, found.revision) == (
        0x80B5, "Test Drives GmbH", "TD MICRO 4", 3,
    )  # fmt: skip
    assert found.station_type == 0
    assert found.texts["ordernumber"] == "TD4-PB00-0AA0"
    assert found.texts["info_text"].endswith("DP-V1 (data record 47); füR Prüfzwecke")
    assert found.family is not None
    assert (found.family.main, found.family.name) == (1, "Drives")
    assert found.family.sub == ("Inverter", "Test Drives")
    rates = [9_600, 19_200, 45_450, 93_750, 187_500, 500_000, 1_500_000, 3_000_000,
             6_000_000, 12_000_000]  # fmt: skip
    assert sorted(found.baud_rates) == rates
    assert found.max_tsdr == dict(zip(rates, [15] * 6 + [25, 50, 100, 200], strict=True))
    assert found.supports(19_200) is True
    assert found.supports(38_400) is False
    assert found.user_prm == b"\x00\x00\x00"
    assert found.dpv1 is not None
    assert (found.dpv1.max_data, found.dpv1.response_timeout, found.dpv1.read_write) == (
        240, pytest.approx(0.01), True,
    )  # fmt: skip
    assert found.modular and found.max_modules == 1
    assert [(m.reference, m.name, m.cfg.hex(" ")) for m in found.modules] == [
        (20, "Standard Telegram 1", "00 e1 d1"),
        (21, "4 PKW,  2 PZD  (PPO 1)", "f3 f1"),
        (22, "0 PKW,  2 PZD  (PPO 3)", "00 f1"),
        (41, "4 PKW,  4 PZD whole cons.", "f3 e3 d3"),
        (42, "4 PKW,  4 PZD word cons.", "f3 63 53"),
        (60, "-- PZD > 4: larger sizes only --", "00"),
        (61, "4 PKW,  6 PZD  (PPO 2)", "f3 f5"),
        (63, "0 PKW,  6 PZD  (PPO 4)", "00 f5"),
    ]
    assert found.modules[1].info == "PPO 1 of PROFIdrive version 2"
    ppos = {gsd.ppo_of(m): m.reference for m in found.modules if gsd.ppo_of(m)}
    assert ppos == {1: 21, 3: 22, 2: 61, 4: 63}
    for number, kind in PPO_TYPES.items():
        module = gsd.module_for_ppo(found, kind)
        assert (module.reference if module else None) == ppos.get(number)
        if module is not None:
            assert dp_services.io_lengths(module.cfg) == (kind.length, kind.length)
    assert found.unit_diag == {0: "Fault present", 1: "Alarm present"}
    (area,) = found.unit_diag_areas
    assert (area.first, area.last, dict(area.values)) == (
        16, 23, {0: "no fault", 7: "converter fault; see r0947"},
    )  # fmt: skip
    assert found.warnings == ()


@pytest.mark.parametrize(
    "variant",
    ["crlf", "cr", "utf8_bom", "utf8", "ctrl_z_end", "no_final_newline", "tabs"],
)
def test_the_same_file_in_every_encoding_and_line_end(variant: str) -> None:
    text = mm4_bytes().decode("latin-1")
    if variant == "crlf":
        data = text.replace("\n", "\r\n").encode("latin-1")
    elif variant == "cr":
        data = text.replace("\n", "\r").encode("latin-1")
    elif variant == "utf8_bom":
        data = "\ufeff".encode() + text.encode()
    elif variant == "utf8":
        data = text.encode()
    elif variant == "ctrl_z_end":
        data = text.encode("latin-1") + b"\x1a"
    elif variant == "no_final_newline":
        data = text.rstrip("\n").encode("latin-1")
    else:
        data = re.sub(r" {2,}", "\t", text).encode("latin-1")
    whole = gsd.parse(gsd.decode(mm4_bytes()))
    other = gsd.parse(gsd.decode(data))
    if variant == "tabs":  # blanks inside quoted names became tabs too
        assert [m.cfg for m in other.modules] == [m.cfg for m in whole.modules]
        other = whole
    assert other == whole


# The blocks of the file, as the specification delimits them: a piece of the file is a
# line, or a block from its first line to its end line.
_BLOCKS = {
    "module": "endmodule",
    "prmtext": "endprmtext",
    "extuserprmdata": "endextuserprmdata",
    "unitdiagtype": "endunitdiagtype",
    "unit_diag_area": "unit_diag_area_end",
    "slotdefinition": "endslotdefinition",
}


def pieces(text: str) -> list[str]:
    """The file after its header in statements and blocks, continuation lines kept."""
    lines = text.split("\n")
    start = next(i for i, line in enumerate(lines) if line.strip().casefold() == "#profibus_dp")
    out: list[str] = []
    current: list[str] = []
    end: str | None = None
    for line in lines[start + 1 :]:
        current.append(line)
        code = line.split(";", 1)[0].strip()
        if code.endswith("\\"):
            continue
        word = re.split(r"[\s=(]", current[0].strip(), maxsplit=1)[0].casefold()
        if end is None and word in _BLOCKS:  # a completed first line: a block begins
            end = _BLOCKS[word]
        if end is None or code.casefold() == end:
            out.append("\n".join(current))
            current, end = [], None
    return [p for p in out if p.split(";", 1)[0].strip()]


def test_the_file_fed_piece_by_piece_says_what_the_whole_says() -> None:
    text = mm4_bytes().decode("latin-1")
    whole = gsd.parse(text)
    parts = pieces(text)
    assert len(parts) > 60
    modules = []
    for part in parts:
        found = read(part)  # every statement and block is read alone too
        assert [w for w in found.warnings if "no MaxTsdr" not in w] == [], part
        modules += found.modules
        if "_supp" in part and "M" not in part.split("_")[0]:
            assert found.baud_rates <= whole.baud_rates
        if part.casefold().startswith("maxtsdr_"):
            ((rate, bits),) = found.max_tsdr.items()
            assert whole.max_tsdr[rate] == bits
    assert tuple(modules) == whole.modules


# ------------------------------------------------------ every keyword class


def test_keywords_that_begin_with_a_digit_or_carry_a_rate() -> None:
    found = read(
        "9.6_supp = 1\n19.2_supp=1\n31.25_supp = 0\n45.45_supp = 1\n93.75_supp = 1\n"
        "187.5_supp = 1\n500_supp = 1\n1.5M_supp = 1\n3m_SUPP = 1\n6M_supp = 0\n12M_supp = 1\n"
        "MaxTsdr_9.6 = 60\nMAXTSDR_1.5m = 150\nMaxTsdr_12M = 800\n24V_Pins = 2\n"
        "24V Pins = 0\n"
    )
    assert sorted(found.baud_rates) == [9_600, 19_200, 45_450, 93_750, 187_500, 500_000,
                                        1_500_000, 3_000_000, 12_000_000]  # fmt: skip
    assert found.max_tsdr == {9_600: 60, 1_500_000: 150, 12_000_000: 800}
    missing = [19_200, 45_450, 93_750, 187_500, 500_000, 3_000_000]
    assert found.warnings == tuple(f"no MaxTsdr for the supported rate {r}" for r in missing)


def test_keywords_are_case_insensitive() -> None:
    found = gsd.parse(
        '#PROFIBUS_DP\nIDENT_NUMBER = 0x0402\nvendor_name = "V"\nMODEL_NAME="M"\n'
        'gsd_revision = 5\nmodule = "A" 0xF1\n7\nENDMODULE\n'
    )
    assert (found.ident, found.vendor, found.model, found.revision) == (0x402, "V", "M", 5)
    assert [(m.name, m.reference) for m in found.modules] == [("A", 7)]


def test_keywords_with_an_argument_a_bang_or_a_blank() -> None:
    found = read(
        'Unit_Diag_Bit( 0) = "first"\nUnit_Diag_Bit(0x0024) = "hex index"\n'
        'Unit_Diag_!Bit(3) = "bit 3 clear"\nUnit_Diag_Not_Bit(4) = "bit 4 clear"\n'
        'Channel_Diag(16) = "Error"\nX_Unit_Diag_Bit(40) = "x"\n'
        'PrmText = 1\nText (0) = "Parameter set 1"\nText(0x0402) = "R-4W 150 ohms"\n'
        "EndPrmText\n"
    )
    assert found.unit_diag == {0: "first", 0x24: "hex index"}
    assert found.prm_texts == {1: {0: "Parameter set 1", 0x402: "R-4W 150 ohms"}}
    assert found.warnings == ()


def test_comments_after_values_and_quotes_that_hold_semicolons_and_equals() -> None:
    found = read(
        'Vendor_Name = "A; B = C" ; the vendor\n'
        "Slave_Family=0@Machine Vision;0 = General\n"
        "Repeater_Ctrl_Sig = 2 ; RTS -> CNTR-P, CNTR-N = NC\n"
        'Model_Name = "M"   ;\n'
        'Module = "A" 0xF1 ; a module\n1 ; its number\nEndModule; its end\n'
    )
    assert (found.vendor, found.model) == ("A; B = C", "M")
    assert found.family == gsd.SlaveFamily(0, ("Machine Vision",))
    assert [(m.name, m.cfg, m.reference) for m in found.modules] == [("A", b"\xf1", 1)]


@pytest.mark.parametrize(
    ("family", "main", "sub"),
    [("3@TdF@SIMATIC", 3, ("TdF", "SIMATIC")), ("9", 9, ()),
     ("2@Départ-moteur@Démarreur", 2, ("Départ-moteur", "Démarreur"))],
)  # fmt: skip
def test_slave_families(family: str, main: int, sub: tuple[str, ...]) -> None:
    found = read(f"Slave_Family = {family}\n")
    assert found.family == gsd.SlaveFamily(main, sub)


def test_continuation_lines() -> None:
    found = read(
        "User_Prm_Data_Len = 5\n"
        "User_Prm_Data = 0x01,0x02, \\\n  0x03, \\   \n  0x04,\\ ; a comment after it\n  0x05\n"
        'Info_Text = "one \\\nline, \\\ntwo"\n'
        'Module = "Basic \\\nType" \\\n  0xF3, \\\n  0xF1\n2\nEndModule\n'
    )
    assert found.user_prm == bytes((1, 2, 3, 4, 5))
    assert found.texts["info_text"] == "one line, two"
    assert [(m.name, m.cfg) for m in found.modules] == [("Basic Type", b"\xf3\xf1")]


def test_text_before_the_header_and_lines_that_close_blocks() -> None:
    found = gsd.parse(
        "=========================\n  TD 100 (a banner without its ;)\n=====\n"
        + HEAD
        + 'SlotDefinition\nSlot(1) = "Data" 1 1-2\nEndSlotDefinition\n'
        "Physical_Interface = 1\nTransmission_Delay_9.6 = 0\nEnd_Physical_Interface\n"
        "Jokerblock_Type = 1\nEnd_Jokerblock_Type\n"
        "Version_Firmware_Download\nVersion = 1\nEnd_Version_Firmware_Download\n"
        'UnitDiagType = 129\nX_Unit_Diag_Area = 24 - 24\nX_Value(0) = "a"\n'
        "X_Unit_Diag_Area_End\nEndUnitDiagType\n"
        'Unit_Diag_Area = 16-17\nValue(0) = "off"\nValue(1) = "on = 1"\nUnit_Diag_Area_End\n'
    )
    assert found.ident == 1
    assert found.unit_diag_areas[0].values == {0: "off", 1: "on = 1"}
    assert found.warnings == ()


def test_module_reference_numbers_and_areas() -> None:
    found = read(
        'Module = "A" 0x13\n0x0001\nInfo_Text = "first"\nEndModule\n'
        'Module = "B" 0x23\nExt_Module_Prm_Data_Len = 09\n12\nData_Area_Beg\nArea_Name = "x"\n'
        "Data_Area_End\nEndmodule   \n"
        'Module = "C" 0X60 0x01\nEndModule\n'
    )
    assert [(m.name, m.cfg, m.reference, m.info) for m in found.modules] == [
        ("A", b"\x13", 1, "first"),
        ("B", b"\x23", 12, ""),
        ("C", b"\x60\x01", None, ""),
    ]
    assert found.modules[1].user_prm == bytes(9)  # Ext_Module_Prm_Data_Len, zero-filled


def test_ext_user_prm_data_with_every_type_and_number_form() -> None:
    found = read(
        'PrmText = 1\nText(0) = "off"\nText(1) = "on"\nEndPrmText\n'
        'ExtUserPrmData = 1 "Gain"\nSigned16 -32768 -32768-32767\nEndExtUserPrmData\n'
        'ExtUserPrmData = 2 "Mode"\nBitArea(0-7) 0x54 0x5b,0x54,0x10\nEndExtUserPrmData\n'
        'ExtUserPrmData = 3 "On"\nBit(7) 1 0-1\nPrm_Text_Ref = 1\nChangeable = 0\n'
        "Visible = 0\nEndExtUserPrmData\n"
        'ExtUserPrmData = 4 "Word"\nUnsigned16 0x4802 0-0xffff\nEndExtUserPrmData\n'
        'ExtUserPrmData = 5 "Long"\nSigned32 -2 -10-10\nEndExtUserPrmData\n'
        "Max_User_Prm_Data_Len = 12\n"
        "Ext_User_Prm_Data_Const(0) = 0x00,0x00,0x00, \\\n 0x0F\n"
        "Ext_User_Prm_Data_Ref( 0 ) = 1\nExt_User_Prm_Data_Ref(2) = 2\n"
        "Ext_User_Prm_Data_Ref(3) = 3\nExt_User_Prm_Data_Ref(4) = 4\n"
        "Ext_User_Prm_Data_Ref(6) = 5\n"
        "User_Prm_Data_Len = 1\nUser_Prm_Data = 0xFF\n"  # ignored beside the Ext entries
    )
    assert found.user_prm == bytes.fromhex("8000 54 8F 4802 FFFFFFFE")
    first, mode, flag = (found.prm_definitions[n] for n in (1, 2, 3))
    assert (first.default, first.allowed, first.is_range, first.type_name) == (
        -32768, (-32768, 32767), True, "Signed16",
    )  # fmt: skip
    assert (mode.allowed, mode.is_range, mode.type_name) == ((0x5B, 0x54, 0x10), False,
                                                              "BitArea(0-7)")  # fmt: skip
    assert (flag.text_ref, flag.changeable, flag.visible) == (1, False, False)


def test_plain_user_prm_data_padded_to_its_length() -> None:
    found = read("User_Prm_Data_Len = 4\nUser_Prm_Data = 0,1\n")
    assert found.user_prm == b"\x00\x01\x00\x00"


def test_module_parameters_follow_the_slaves() -> None:
    found = read(
        'ExtUserPrmData = 7 "Gain"\nSigned8 -2 -10-10\nEndExtUserPrmData\n'
        'Module = "Analog" 0x13\nExt_User_Prm_Data_Const(0) = 0x05\n'
        "Ext_User_Prm_Data_Ref(1) = 7\nEndModule\nUser_Prm_Data = 0x09\n"
    )
    module = found.module("Analog")
    assert module.user_prm == b"\x05\xfe"
    assert found.prm_for([module]) == b"\x09\x05\xfe"
    with pytest.raises(LocalProtocolError, match="at most 237"):
        found.prm_for([module] * 120)


def test_unknown_keywords_are_ignored_never_refused() -> None:
    found = read(
        "FixPresetModules = 1\nF_ParamDescCRC = 0x1234\nTBASE_DP = 375\n"
        'Some_Future_Keyword(3) = "x" 1, 2\nOnlySpecialModules = 0\n'
    )
    assert found.ident == 1 and found.warnings == ()


def test_the_dpv1_keys() -> None:
    assert read("").dpv1 is None  # no DPV1_Slave: a DP-V0 slave
    found = read("DPV1_Slave = 1\nC1_Read_Write_supp = 1\nC1_Max_Data_Len = 200\n"
                 "C1_Response_Timeout = 100\n")  # fmt: skip
    assert found.dpv1 is not None
    assert (found.dpv1.max_data, found.dpv1.response_timeout, found.dpv1.read_write) == (
        200, 1.0, True,
    )  # fmt: skip
    bare = read("DPV1_Slave = 1\n").dpv1
    assert bare is not None and (bare.max_data, bare.read_write) == (240, False)


def test_what_is_read_past_is_told() -> None:
    found = read(
        "this is not a statement\nEndModule\n42\n"
        'Module = A 0xF1\nEndModule\nModule = "B"\nEndModule\nModule = "C" 0x1F1\nEndModule\n'
        'Module = "D" 0xF1\nExt_User_Prm_Data_Ref(0) = 9\nEndModule\n'
        'Module = "E" 0xF1\nEndModule\n'
    )
    assert [m.name for m in found.modules] == ["E"]
    told = {int(w.split(":")[0].removeprefix("line ")): w for w in found.warnings}
    expected = {3: "this is not", 4: "EndModule", 5: "'42'", 6: "quoted name",
                8: "no configuration bytes", 10: "not a byte", 13: "undefined"}  # fmt: skip
    assert told.keys() == expected.keys()
    for line, what in expected.items():
        assert what in told[line], (line, told[line])


def test_unknown_module_name() -> None:
    with pytest.raises(LocalProtocolError, match=r"no module 'PPO 9'.*'PPO 1'"):
        read('Module = "PPO 1" 0xF3,0xF1\nEndModule\n').module("PPO 9")


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        ("", 0, "no #Profibus_DP"),
        ("Ident_Number = 1\n", 0, "no #Profibus_DP"),
        ("#Profibus_DP\nVendor_Name = 'x'\n", 0, "no Ident_Number"),
        ("#Profibus_DP\nIdent_Number = 0xZZ\n", 2, "not a number"),
        ("#Profibus_DP\nIdent_Number = 0x10000\n", 2, "not 16 bits"),
        ("#Profibus_DP\nIdent_Number = 1\nUser_Prm_Data_Len = 999999999\n", 3, "outside 0-237"),
        ("#Profibus_DP\nIdent_Number = 1\nMaxTsdr_19.2 = many\n", 3, "not a number"),
        ('#Profibus_DP\nIdent_Number = 1\nModule = "A" 0xF1\n', 3, "without its endmodule"),
        ('#Profibus_DP\nIdent_Number = 1\nModule = "A" 1\nModule = "B" 2\nEndModule\n', 4,
         "Module inside module"),
        ("#Profibus_DP\nIdent_Number = 1\nExt_User_Prm_Data_Ref(0) = 9\n", 3, "undefined"),
        ("#Profibus_DP\nIdent_Number = 1\nExt_User_Prm_Data_Const = 1\n", 3, "offset"),
        ('#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\n', 3, "without its"),
        ('#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\nFloat32 1 0-2\n'
         "EndExtUserPrmData\nExt_User_Prm_Data_Ref(0) = 1\n", 6, "unknown data type"),
        ('#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\nUnsigned8 300 0-2\n'
         "EndExtUserPrmData\nExt_User_Prm_Data_Ref(0) = 1\n", 6, "does not fit"),
        ('#Profibus_DP\nIdent_Number = 1\nExtUserPrmData = 1 "x"\nBit(9) 1 0-1\n'
         "EndExtUserPrmData\nExt_User_Prm_Data_Ref(0) = 1\n", 6, "outside 0-7"),
        ("#Profibus_DP\nIdent_Number = 1\nDPV1_Slave = 1\nC1_Max_Data_Len = 241\n", 4,
         "C1_Max_Data_Len 241"),
    ],
)  # fmt: skip
def test_errors_name_the_line(text: str, line: int, message: str) -> None:
    with pytest.raises(GsdError, match=message) as caught:
        gsd.parse(text)
    assert caught.value.line == line
    if line:
        assert str(caught.value).startswith(f"GSD line {line}:")


def test_a_bad_definition_no_ref_uses_is_only_told() -> None:
    found = read('ExtUserPrmData = 1 "x"\nFloat32 1 0-2\nEndExtUserPrmData\n')
    assert found.warnings == ("line 4: unknown data type 'Float32'",)


@given(st.text(max_size=400))
def test_any_text_is_read_or_refused_clearly(text: str) -> None:
    with contextlib.suppress(GsdError):
        gsd.parse(HEAD + text)


@given(st.binary(max_size=400))
def test_any_bytes_are_read_or_refused_clearly(data: bytes) -> None:
    with contextlib.suppress(GsdError):
        gsd.parse(gsd.decode(HEAD.encode() + data))


@given(st.binary(max_size=8), st.sampled_from(["\n", "\r\n", "\r"]), st.booleans())
def test_user_prm_data_round_trip(data: bytes, newline: str, continued: bool) -> None:
    items = [f"0x{b:02X}" for b in data]
    sep = ", \\" + newline + "  " if continued else ","
    body = sep.join(items)
    text = newline.join(
        ["#Profibus_DP", "ident_number = 7", f"User_Prm_Data_Len = {len(data)}"]
        + ([f"User_Prm_Data = {body}"] if data else [])
    )
    assert gsd.parse(text + newline).user_prm == data


# ------------------------------------------------ what users bring: a folder of files


def _folder() -> list[Path]:
    folder = os.environ.get("PKWBUS_GSD_DIR")
    if not folder:
        return []
    return sorted(p for p in Path(folder).rglob("*") if p.suffix.casefold() in EXTENSIONS)


@pytest.mark.skipif(not os.environ.get("PKWBUS_GSD_DIR"), reason="PKWBUS_GSD_DIR is not set")
def test_every_gsd_file_of_a_folder_is_read() -> None:
    files = _folder()
    assert files, "PKWBUS_GSD_DIR holds no GSD file"
    refused = {}
    for path in files:
        try:
            found = gsd.parse(gsd.decode(path.read_bytes()))
        except GsdError as exc:
            refused[path.name] = str(exc)
            continue
        assert 0 <= found.ident <= 0xFFFF
        for module in found.modules:
            assert module.cfg, path
    assert not refused, refused
