"""The error numbers of a PROFIdrive parameter response (format 0x44), in words.

Texts as the vendors print them:

- 0x00-0x17: SINAMICS CU240S Operating Instructions (07/2008, FW 3.2), table
  6-25 "Explanation of error values in parameter responses" (the same rows as
  the SINAMICS S120 Function Manual 06/2012, table 9-33);
- 0x10, 0x18: SINAMICS G130 Operating Instructions (07/2016), table 6-15;
- 0x19: the SINAMICS S210 alarm list (faults F01042/F01082, "fault cause"),
  which numbers the same errors in decimal ("25: Drive object does not exist").

Numbers from 0x65 on are the manufacturer's own. Danfoss's (dialect
``danfoss-pcv``) are those of the VLT FC 300 PROFIBUS Operating Instructions
MG.33.C2.02, "Error codes for DP V1 parameter requests" (the same table as the
VLT PROFIBUS DP MCA 101 Programming Manual, 5.2.22); any other is shown with
its number, for the drive's manual.
"""

from __future__ import annotations

from typing import Final

__all__ = ["ERRORS", "VENDOR_ERRORS", "error_text"]

ERRORS: Final[dict[int, str]] = {
    0x00: "Illegal parameter number",
    0x01: "Parameter value cannot be changed",
    0x02: "Lower or upper value limit exceeded",
    0x03: "Invalid subindex",
    0x04: "No array",
    0x05: "Wrong data type",
    0x06: "Illegal set operation (only reset allowed)",
    0x07: "Description element cannot be changed",
    0x09: "No description data",
    0x0B: "No operating priority",
    0x0F: "No text array exists",
    0x10: "Read job will not be executed",
    0x11: "Request cannot be executed due to operating status",
    0x14: "Illegal value",
    0x15: "Response too long",
    0x16: "Illegal parameter address",
    0x17: "Illegal format",
    0x18: "Number of values inconsistent",
    0x19: "Drive object does not exist",
}

_VENDOR_FROM: Final = 0x65

VENDOR_ERRORS: Final[dict[str, dict[int, str]]] = {
    "danfoss-pcv": {
        0x65: "Wrong axis: action not possible with this axis",
        0x66: "Unknown service request",
        0x67: "This service is not possible with multi parameter access",
        0x68: "Parameter value can not be read from bus",
    },
}


def error_text(number: int, dialect: str = "") -> str:
    """The words of a PROFIdrive error number (``dialect``: the drive's, for its own)."""
    known = ERRORS.get(number) or VENDOR_ERRORS.get(dialect, {}).get(number)
    if known is not None:
        return known
    if number >= _VENDOR_FROM:
        return f"manufacturer-specific error {number} ({number:#04x}): see the drive's manual"
    return f"error {number} ({number:#04x}), not defined by PROFIdrive"
