"""The fields of a PKW block: PKE and IND (with the page index), PWE, width and store.

PKE carries the identifier (AK) and the parameter number, IND the subindex and
the page index or text marker, in the layout of :class:`IndLayout` (SINAMICS
G120 CU240B-2/CU240E-2 Operating Instructions, section 6.3; Danfoss VLT Design
Manual, section 8.4.7 "The PKE Field").

Raises :class:`~pkwbus.protocol.errors.LocalProtocolError` for a PNU or page
offset that cannot be encoded, and
:class:`~pkwbus.protocol.errors.RemoteProtocolError` for a PKE, IND or PWE
received that cannot be what the dialect sends.
"""

from __future__ import annotations

import enum

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Dialect, IndLayout
from pkwbus.protocol.values.types import Width as Width

__all__ = [
    "PAGE_SIZE",
    "Store",
    "Width",
    "decode_pke_ind",
    "decode_pwe",
    "encode_pke_ind",
    "page_index",
    "page_multiple",
]

PAGE_SIZE = 2000
_PNU_MASK_11 = 0x7FF
# Bits of the page index byte for a + 2b + 4c + 8d + 16e + 32f (SINAMICS CU240S
# operating instructions, USS page index).
_PAGE_BITS = (0x80, 0x10, 0x20, 0x40, 0x04, 0x08)


class Store(enum.StrEnum):
    RAM = "ram"
    EEPROM = "eeprom"


def page_index(multiple: int) -> int:
    """The page index byte for a PNU offset of ``multiple`` * 2000."""
    if not 0 <= multiple < 64:
        raise LocalProtocolError(f"page offset {multiple * PAGE_SIZE} cannot be encoded")
    return sum(bit for n, bit in enumerate(_PAGE_BITS) if multiple >> n & 1)


def page_multiple(page: int) -> int:
    """Inverse of :func:`page_index`: the multiple of 2000 a page index byte stands for."""
    return sum(1 << n for n, bit in enumerate(_PAGE_BITS) if page & bit)


def encode_pke_ind(
    dialect: Dialect, layout: IndLayout, ak: int, pnu: int, subindex: int, high: int = 0
) -> tuple[int, int]:
    """PKE and IND words for ``pnu`` and ``subindex`` (``high``: FC text marker)."""
    dialect.check_pnu(pnu)
    page = 0
    if dialect.pnu_bits == 12:
        number = pnu
    elif dialect.page_index:
        multiple, number = divmod(pnu, PAGE_SIZE)
        page = page_index(multiple)
    else:
        number = pnu
    pke = (ak << 12) | number
    other = page or high
    if layout is IndLayout.USS:
        return pke, (other << 8) | subindex
    return pke, (subindex << 8) | other


def decode_pke_ind(dialect: Dialect, layout: IndLayout, pke: int, ind: int) -> tuple[int, int, int]:
    """AK, PNU (page index applied) and subindex of a PKE and IND."""
    if layout is IndLayout.USS:
        subindex, other = ind & 0xFF, ind >> 8
    else:
        subindex, other = ind >> 8, ind & 0xFF
    ak = pke >> 12
    if dialect.pnu_bits == 12:
        return ak, pke & 0xFFF, subindex
    pnu = pke & _PNU_MASK_11
    if dialect.page_index:
        if pnu >= PAGE_SIZE:
            raise RemoteProtocolError(f"PNU field {pnu} beside a page index (1-1999 allowed)")
        pnu += PAGE_SIZE * page_multiple(other)
        if pnu > dialect.max_pnu:
            raise RemoteProtocolError(f"page index {other:#04x} makes PNU {pnu}, above 65535")
    return ak, pnu, subindex


def decode_pwe(data: bytes) -> tuple[int, int]:
    """(PWE as a double word, PWE low word); a 3-word block has only the low word."""
    if len(data) >= 4:
        value = int.from_bytes(data[:4], "big")
        return value, value & 0xFFFF
    if len(data) == 2:
        low = int.from_bytes(data, "big")
        return low, low
    raise RemoteProtocolError(f"PWE of {len(data)} bytes")
