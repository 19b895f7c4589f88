"""A GSD file's text as statements: the syntax of the PROFIBUS GSD specification
(revisions 1 to 5), as vendors write it.

- The file begins with a ``#Profibus_DP`` line; what stands before it (a
  banner, even one without its ``;``) is not part of the description.
- ``;`` starts a comment, outside quotes, also after a value
  (``24V_Pins=2; Signal M24V``).
- A line that ends with ``\\`` goes on in the next one (a quoted text too).
- A statement is ``Keyword = value``, ``Keyword(argument) = value``, or a line
  without ``=``: a block's end (``EndModule``, ``Unit_Diag_Area_End``), a
  block's beginning (``SlotDefinition``), a module's reference number, the
  data type line of an ``ExtUserPrmData``. A keyword may begin with a digit
  (``9.6_supp``, ``24V_Pins``) or carry a rate (``MaxTsdr_1.5M``) or a ``!``
  (``Unit_Diag_!Bit(3)``); keywords are case-insensitive.
- Lines end with CR LF, LF or CR. The text is Latin-1 (ISO 8859-1); a file in
  UTF-8 is read as UTF-8.

Pure: bytes or text in, statements out.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError

__all__ = [
    "HEADER",
    "Bare",
    "GsdError",
    "Setting",
    "Statement",
    "byte_list",
    "decode",
    "number",
    "quoted",
    "statements",
]

HEADER: Final = "#profibus_dp"
_BOM: Final = "\ufeff"
# Physical line ends: CR LF, LF, CR; never the other characters str.splitlines takes
# (a Latin-1 byte 0x85 or 0x1C is text, not a line end).
_LINE_END = re.compile(r"\r\n|\r|\n")
_SETTING = re.compile(r'^([^=("]+?)\s*(?:\(([^)]*)\))?\s*=\s*(.*)$')
_QUOTED = re.compile(r'^"([^"]*)"?\s*(.*)$')
_NUMBER = re.compile(r"^[+-]?(0x[0-9a-f]+|\d+)$", re.IGNORECASE)
# Characters that end a file's text in old editors (Ctrl-Z) or pad it (NUL).
_PADDING: Final = " \t\x00\x1a\x0c"


class GsdError(LocalProtocolError):
    """A GSD file this reader cannot use; ``line`` is where (1-based, 0 for the whole file)."""

    def __init__(self, line: int, message: str) -> None:
        self.line = line
        self.reason = message
        super().__init__(f"GSD line {line}: {message}" if line else f"GSD: {message}")


@dataclass(frozen=True, slots=True)
class Setting:
    """``Keyword = value`` or ``Keyword(argument) = value``; ``key`` casefolded."""

    line: int
    key: str
    argument: str | None
    value: str


@dataclass(frozen=True, slots=True)
class Bare:
    """A line without ``=``: a block's end or beginning, a number, a data type line."""

    line: int
    text: str

    @property
    def key(self) -> str:
        words = self.text.split(None, 1)
        return words[0].split("(", 1)[0].casefold() if words else ""


Statement = Setting | Bare


def decode(data: bytes) -> str:
    """A GSD file's bytes as text: UTF-8 where they are UTF-8 (with or without a BOM),
    else Latin-1, the specification's character set (every byte is a character)."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def statements(text: str) -> list[Statement]:
    """The statements after the ``#Profibus_DP`` line; a :class:`GsdError` without one."""
    lines = _LINE_END.split(text.removeprefix(_BOM))
    header = _header(lines)
    out: list[Statement] = []
    for number, line in _logical(lines, header + 1):
        match = _SETTING.match(line)
        if match is None:
            out.append(Bare(number, line))
            continue
        key, argument, value = match.groups()
        out.append(
            Setting(
                number,
                " ".join(key.split()).casefold(),
                argument.strip() if argument is not None else None,
                value.strip(),
            )
        )
    return out


def _header(lines: list[str]) -> int:
    """The index of the ``#Profibus_DP`` line."""
    for i, raw in enumerate(lines):
        text, _ = _cut_comment(raw, False)
        if text.strip(_PADDING).casefold() == HEADER:
            return i
    raise GsdError(0, "not a GSD file: no #Profibus_DP line")


def _logical(lines: list[str], start: int) -> list[tuple[int, str]]:
    """(first line number, text) of each logical line from ``lines[start]`` on: comments
    cut, continued lines joined (inside a quoted text without a blank)."""
    out: list[tuple[int, str]] = []
    pending: list[str] = []
    first = 0
    quoted = False
    for index in range(start, len(lines)):
        if not pending:
            first, quoted = index + 1, False
        text, quoted = _cut_comment(lines[index], quoted)
        text = text.rstrip(_PADDING)
        if text.endswith("\\"):
            pending.append(text[:-1] if quoted else text[:-1] + " ")
            continue
        pending.append(text)
        whole = "".join(pending).strip(_PADDING)
        pending = []
        if whole:
            out.append((first, whole))
    if pending and (whole := "".join(pending).strip(_PADDING)):
        out.append((first, whole))
    return out


def _cut_comment(line: str, quoted: bool) -> tuple[str, bool]:
    """The line up to a ``;`` outside quotes, and whether a quote is open at its end."""
    for i, char in enumerate(line):
        if char == '"':
            quoted = not quoted
        elif char == ";" and not quoted:
            return line[:i], quoted
    return line, quoted


# --------------------------------------------------------------------- values


def number(token: str, line: int, what: str = "") -> int:
    """A decimal or ``0x`` hexadecimal number."""
    text = token.strip()
    if _NUMBER.match(text) is None:
        about = f"{what}: " if what else ""
        raise GsdError(line, f"{about}{text[:40]!r} is not a number")
    sign = -1 if text.startswith("-") else 1
    digits = text.lstrip("+-")
    if digits[:2].casefold() == "0x":
        return sign * int(digits[2:], 16)
    return sign * int(digits, 10)


def byte_list(value: str, line: int, what: str = "") -> bytes:
    """Bytes written as numbers separated by commas or blanks (``0xF3,0xF1``, ``0 0 1``)."""
    numbers = [number(v, line, what) for v in re.split(r"[,\s]+", value.strip()) if v]
    bad = [n for n in numbers if not 0 <= n <= 255]
    if bad:
        about = f"{what}: " if what else ""
        raise GsdError(line, f"{about}{bad[0]} is not a byte")
    return bytes(numbers)


def quoted(value: str, line: int, what: str) -> tuple[str, str]:
    """A quoted text at the start of ``value`` and what follows it; a text without its
    closing quote runs to the end of the line."""
    match = _QUOTED.match(value)
    if match is None:
        raise GsdError(line, f"{what}: expected a quoted name in {value[:40]!r}")
    return match.group(1), match.group(2)
