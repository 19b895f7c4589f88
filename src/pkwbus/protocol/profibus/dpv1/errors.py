"""The error codes of a negative DP-V1 response (MSAC_C1 read or write), in words.

Error_Decode and Error_Code_1 as the Beckhoff EL6731 documentation ("DPV1
Error Codes") and the ABB FPBA-01 PROFIBUS DP adapter module User's manual
(table 10, "DP-V1 error response: Error codes") name them: the error class in
the high nibble of Error_Code_1 (10 application, 11 access, 12 resource), the
code in the low one. Error_Code_2 is the slave's own ("not defined in the DPV1
standard, and are therefore to be found in the slave's manual").
"""

from __future__ import annotations

from typing import Final

__all__ = ["CODES", "DECODES", "error_code_text", "error_decode_text"]

DECODES: Final[dict[int, str]] = {0x80: "DPV1", 0xFE: "FMS", 0xFF: "HART"}

_CLASSES: Final[dict[int, str]] = {0x0A: "Application", 0x0B: "Access", 0x0C: "Resource"}

CODES: Final[dict[int, str]] = {
    0xA0: "Application, Read Error",
    0xA1: "Application, Write Error",
    0xA2: "Application, Module Failure",
    0xA8: "Application, Version Conflict",
    0xA9: "Application, Feature Not Supported",
    0xB0: "Access, Invalid Index",
    0xB1: "Access, Write Length Error",
    0xB2: "Access, Invalid Slot",
    0xB3: "Access, Type Conflict",
    0xB4: "Access, Invalid Area",
    0xB5: "Access, State Conflict",
    0xB6: "Access, Access Denied",
    0xB7: "Access, Invalid Range",
    0xB8: "Access, Invalid Parameter",
    0xB9: "Access, Invalid Type",
    0xC0: "Resource, Read Constrain Conflict",
    0xC1: "Resource, Write Constrain Conflict",
    0xC2: "Resource, Busy",
    0xC3: "Resource, Unavailable",
}


def error_decode_text(decode: int) -> str:
    """The words of an Error_Decode byte."""
    return DECODES.get(decode, f"error decode {decode:#04x}")


def error_code_text(code1: int) -> str:
    """The words of an Error_Code_1 byte."""
    known = CODES.get(code1)
    if known is not None:
        return known
    group = _CLASSES.get(code1 >> 4)
    if group is not None:
        return f"{group}, code {code1 & 0x0F} (user-specific or reserved)"
    return f"error class {code1 >> 4} (user-specific), code {code1 & 0x0F}"
