"""The per-dialect tables, worded as the manuals word them.

Request and response identifiers with their texts, and fault numbers with
their texts: fc (Danfoss VLT Design Manual, section 8.4.7 "The PKE Field", and
the FC 101 Design Guide's fault list), Siemens uss and profidrive (SINAMICS
G120 CU240B-2/CU240E-2 Operating Instructions 07/2010, section 6.3
"Communication via PROFIBUS", and the SINAMICS/MICROMASTER identifier and fault
lists), danfoss-pcv (Danfoss PROFIBUS manual, section 5.3.4 "RC Content"),
hitachi-sjpb (Hitachi SJ-PB(T) User Manual, chapter 5 "Operating").

Data only: nothing here raises.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from pkwbus.protocol.pkw.dialects.model import Command, Fault, Reply

__all__ = [
    "FC_ARRAY_ALIASES",
    "FC_FAULTS",
    "FC_REQUESTS",
    "FC_RESPONSES",
    "HITACHI_FAULTS",
    "HITACHI_REQUESTS",
    "HITACHI_RESPONSES",
    "PCV_FAULTS",
    "PCV_REQUESTS",
    "PCV_RESPONSES",
    "SIEMENS_FAULTS",
    "SIEMENS_REQUESTS",
    "SIEMENS_RESPONSES",
]

Requests = Mapping[int, tuple[Command, str]]
Responses = Mapping[int, tuple[Reply, str]]


def _faults(rows: list[tuple[int, str, str]]) -> Mapping[int, Fault]:
    return MappingProxyType({n: Fault(n, text, short) for n, text, short in rows})


# ------------------------------------------------------------- Danfoss FC

FC_REQUESTS: Requests = MappingProxyType(
    {
        0: (Command.NONE, "No command"),
        1: (Command.READ, "Read parameter value"),
        2: (Command.WRITE_WORD, "Write parameter value in RAM (word)"),
        3: (Command.WRITE_DWORD, "Write parameter value in RAM (double word)"),
        4: (Command.READ_DESCRIPTION, "Read description"),  # Danfoss FC 300 Design Manual
        13: (Command.WRITE_DWORD_EEPROM, "Write parameter value in RAM and EEprom (double word)"),
        14: (Command.WRITE_WORD_EEPROM, "Write parameter value in RAM and EEprom (word)"),
        15: (Command.TEXT, "Read/write text"),
    }
)
# FC addresses array elements with the ordinary identifiers and IND.
FC_ARRAY_ALIASES: Mapping[Command, int] = MappingProxyType(
    {
        Command.READ_ARRAY: 1,
        Command.WRITE_ARRAY_WORD: 2,
        Command.WRITE_ARRAY_DWORD: 3,
        Command.WRITE_ARRAY_DWORD_EEPROM: 13,
        Command.WRITE_ARRAY_WORD_EEPROM: 14,
    }
)
FC_RESPONSES: Responses = MappingProxyType(
    {
        0: (Reply.NONE, "No response"),
        1: (Reply.WORD, "Parameter value transferred (word)"),
        2: (Reply.DWORD, "Parameter value transferred (double word)"),
        3: (Reply.DESCRIPTION, "Description transferred"),  # Danfoss FC 300 Design Manual
        7: (Reply.REJECTED, "Command cannot be performed"),
        15: (Reply.TEXT, "text transferred"),
    }
)
# The Danfoss VLT Design Manual, section 8.4.7, prints the fault numbers in hex
# (11, 82, 83 = 17, 130, 131); 9, 11, 15, 18 and 132 come from the Danfoss
# FC 101 Design Guide's fault codes.
FC_FAULTS = _faults(
    [
        (0, "The parameter number used does not exit", "illegal parameter number"),
        (1, "There is no write access to the defined parameter", "no write access"),
        (2, "Data value exceeds the parameter's limits", "limit exceeded"),
        (3, "The sub index used does not exit", "illegal subindex"),
        (4, "The parameter is not the array type", "not an array"),
        (5, "The data type does not match the defined parameter", "wrong data type"),
        (9, "Description data not available", "description not available"),
        (11, "No write access", "no write access"),
        (15, "No text available", "no text"),
        (
            0x11,
            "Data change in the defined parameter is not possible in the frequency "
            "converter's present mode. Certain parameters can only be changed when the "
            "motor is turned off",
            "not in present mode",
        ),
        (18, "Other fault", "other fault"),
        (0x82, "There is no bus access to the defined parameter", "no bus access"),
        (
            0x83,
            "Data change is not possible because factory setup is selected",
            "factory setup selected",
        ),
        (132, "No LCP access", "no LCP access"),
    ]
)

# --------------------------------------------------- Siemens USS / PROFIdrive

SIEMENS_REQUESTS: Requests = MappingProxyType(
    {
        0: (Command.NONE, "No request"),
        1: (Command.READ, "Request parameter value"),
        2: (Command.WRITE_WORD, "Change parameter value (word)"),
        3: (Command.WRITE_DWORD, "Change parameter value (double word)"),
        4: (Command.READ_DESCRIPTION, "Request descriptive element"),
        5: (Command.WRITE_DESCRIPTION, "Change descriptive element"),
        6: (Command.READ_ARRAY, "Request parameter value (array)"),
        7: (Command.WRITE_ARRAY_WORD, "Change parameter value (array, word)"),
        8: (Command.WRITE_ARRAY_DWORD, "Change parameter value (array, double word)"),
        9: (Command.READ_ARRAY_COUNT, "Request number of array elements"),
        11: (
            Command.WRITE_ARRAY_DWORD_EEPROM,
            "Change parameter value (array, double word) and store in EEPROM",
        ),
        12: (
            Command.WRITE_ARRAY_WORD_EEPROM,
            "Change parameter value (array, word) and store in EEPROM",
        ),
        13: (
            Command.WRITE_DWORD_EEPROM,
            "Change parameter value (double word) and store in EEPROM",
        ),
        14: (Command.WRITE_WORD_EEPROM, "Change parameter value (word) and store in EEPROM"),
        15: (Command.TEXT, "Read or change text"),
    }
)
SIEMENS_RESPONSES: Responses = MappingProxyType(
    {
        0: (Reply.NONE, "No response"),
        1: (Reply.WORD, "Transfer parameter value (word)"),
        2: (Reply.DWORD, "Transfer parameter value (double word)"),
        3: (Reply.DESCRIPTION, "Transfer descriptive element"),
        4: (Reply.ARRAY_WORD, "Transfer parameter value (array, word)"),
        5: (Reply.ARRAY_DWORD, "Transfer parameter value (array, double word)"),
        6: (Reply.ARRAY_COUNT, "Transfer number of array elements"),
        7: (Reply.REJECTED, "Request cannot be executed"),
        8: (Reply.NO_RIGHTS, "No master control status / no change rights for the PKW interface"),
        9: (Reply.SPONTANEOUS, "Spontaneous message (word)"),
        10: (Reply.SPONTANEOUS, "Spontaneous message (double word)"),
        11: (Reply.SPONTANEOUS, "Spontaneous message (array, word)"),
        12: (Reply.SPONTANEOUS, "Spontaneous message (array, double word)"),
        15: (Reply.TEXT, "Transfer text"),
    }
)
SIEMENS_FAULTS = _faults(
    [
        (0, "Illegal parameter number (PNU)", "illegal parameter number"),
        (1, "Parameter value cannot be changed (read only)", "read only"),
        (2, "Lower or upper value limit exceeded", "limit exceeded"),
        (3, "Invalid subindex", "illegal subindex"),
        (4, "No array", "not an array"),
        (5, "Incorrect data type", "wrong data type"),
        (6, "Setting not permitted (can only be reset)", "only reset allowed"),
        (7, "Descriptive element cannot be changed", "description not changeable"),
        (11, "No master control", "not in master control"),
        (12, "Keyword missing", "keyword missing"),
        (17, "Request cannot be executed because of the operating state", "not in present state"),
        (101, "Parameter number is currently deactivated", "parameter deactivated"),
        (102, "Channel not wide enough", "channel too small"),
        (104, "Illegal parameter value", "impermissible value"),
        (106, "Request not included / task is not supported", "request not implemented"),
        (200, "Below the currently valid lower limit", "below modified limit"),
        (201, "Above the currently valid upper limit", "above modified limit"),
        (204, "No access rights", "no access rights"),
    ]
)

# ------------------------------------------------------ Danfoss PROFIBUS PCV

PCV_REQUESTS: Requests = MappingProxyType(
    {
        0: (Command.NONE, "No request"),
        1: (Command.READ, "Request parameter value"),
        2: (Command.WRITE_WORD, "Change parameter value (word)"),
        3: (Command.WRITE_DWORD, "Change parameter value (long word)"),
        4: (Command.READ_DESCRIPTION, "Request description element"),
        5: (Command.WRITE_DESCRIPTION, "Change description element"),
        6: (Command.READ_ARRAY, "Request parameter value (array)"),
        7: (Command.WRITE_ARRAY_WORD, "Change parameter value (array word)"),
        8: (Command.WRITE_ARRAY_DWORD, "Change parameter value (array long word)"),
        9: (Command.READ_ARRAY_COUNT, "Request number of array elements"),
    }
)
PCV_RESPONSES: Responses = MappingProxyType(
    {
        0: (Reply.NONE, "No response"),
        1: (Reply.WORD, "Transfer parameter value (word)"),
        2: (Reply.DWORD, "Transfer parameter value (long word)"),
        3: (Reply.DESCRIPTION, "Transfer description element"),
        4: (Reply.ARRAY_WORD, "Transfer parameter value (array word)"),
        5: (Reply.ARRAY_DWORD, "Transfer parameter value (array long word)"),
        6: (Reply.ARRAY_COUNT, "Transfer number of array elements"),
        7: (Reply.REJECTED, "Request rejected (including fault number)"),
        8: (Reply.NO_RIGHTS, "Not serviceable by PCV interface"),
    }
)
PCV_FAULTS = _faults(
    [
        (0, "Illegal PNU", "illegal parameter number"),
        (1, "Parameter value cannot be changed.", "read only"),
        (2, "Upper or lower limit exceeded.", "limit exceeded"),
        (3, "Subindex corrupted.", "illegal subindex"),
        (4, "No array", "not an array"),
        (5, "Data type false", "wrong data type"),
        (6, "Cannot be set by user (reset only).", "only reset allowed"),
        (7, "Description element cannot be changed.", "description not changeable"),
        (8, "IR required PPO-write not available.", "PPO-write not available"),
        (9, "Description data not available.", "description not available"),
        (10, "Access group", "access group"),
        (11, "No parameter write access", "no write access"),
        (12, "Key word missing.", "keyword missing"),
        (13, "Text in cyclical transmission not readable.", "text not readable"),
        (14, "Name in cyclical transmission not readable.", "name not readable"),
        (15, "Text array not available", "text array not available"),
        (16, "PPO-write missing", "PPO-write missing"),
        (17, "Request temporarily rejected", "temporarily rejected"),
        (18, "Other fault", "other fault"),
        (19, "Data in cyclical transmission not readable.", "data not readable"),
        (130, "There is no bus access to the parameter called.", "no bus access"),
        (
            131,
            "Data change is not possible because factory set-up has been selected.",
            "factory setup selected",
        ),
    ]
)

# ------------------------------------------------------------ Hitachi SJ-PB

# Requests 4, 5 and 8 and responses 3, 5, 9 and 10 carry the Hitachi SJ-PB(T) User Manual's note
# "Not supported by the SJ-PB(T) option board": the dialect does not have them.
HITACHI_REQUESTS: Requests = MappingProxyType(
    {
        0: (Command.NONE, "No request"),
        1: (Command.READ, "Request parameter value"),
        2: (Command.WRITE_WORD, "Change parameter value (word)"),
        3: (Command.WRITE_DWORD, "Change parameter value (long word)"),
        6: (Command.READ_ARRAY, "Request parameter value (array)"),
        7: (Command.WRITE_ARRAY_WORD, "Change parameter value (array word)"),
        9: (Command.READ_ARRAY_COUNT, "Request number of array elements"),
    }
)
HITACHI_RESPONSES: Responses = MappingProxyType(
    {
        0: (Reply.NONE, "No response"),
        1: (Reply.WORD, "Transfer parameter value (word)"),
        2: (Reply.DWORD, "Transfer parameter value (long word)"),
        4: (Reply.ARRAY_WORD, "Transfer parameter value (array word)"),
        6: (Reply.ARRAY_COUNT, "Request number of array elements"),
        7: (Reply.REJECTED, "Request rejected, followed by fault code (in PWE part)."),
        8: (Reply.NO_RIGHTS, "No parameter change rights by PKW interface"),
    }
)
HITACHI_FAULTS = _faults(
    [
        (0, "Non-admissible parameter number", "illegal parameter number"),
        (1, "Parameter value cannot be changed", "read only"),
        (2, "Upper or lower limit exceeded", "limit exceeded"),
        (3, "Erroneous sub-index", "illegal subindex"),
        (4, "No array", "not an array"),
        (5, "Incorrect data type", "wrong data type"),
        (7, "Descriptive element cannot be changed", "description not changeable"),
        (9, "Descriptive data not available", "description not available"),
        (11, "No parameter change rights", "no change rights"),
        (17, "Task cannot be executed due to operating status", "not in present state"),
        (18, "Other", "other fault"),
        (102, "Task cannot be executed due to communication error.", "communication error"),
        (106, "Illegal Task, Task ID not allowed.", "illegal task"),
    ]
)
