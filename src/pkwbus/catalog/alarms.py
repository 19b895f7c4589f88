"""Alarm, warning and status words and fault numbers in words, from vendors' tables.

A catalog may come with an alarm table, ``data/alarms/<catalog>.yaml``:

- ``words``: bit words (Danfoss 16-90 Alarm Word, 16-92 Warning Word, 16-94
  Ext. Status Word): the text of each bit a named document explains;
- ``codes``: numbers (SINAMICS r0947 fault numbers shown as ``F07801``, r2122
  alarm numbers as ``A07991``; Danfoss 15-30 alarm log error codes), with the
  text of each number a named document explains. ``active``: the parameter
  holds what is active now (a fault buffer's current case); otherwise it is a
  log, decoded for people but never counted as active.

Every entry names its source (a key of ``sources``, a document title and
section). A bit or a number no source explains is shown as its code alone,
never with a text of ours. Pure: data in, alarms out.

Raises :class:`~pkwbus.catalog.loader.CatalogError` for a table that cannot be read.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources
from typing import Literal, Self

from pydantic import BaseModel, ConfigDict, ValidationError, model_validator

from pkwbus.catalog.loader import CatalogError
from pkwbus.notation.problems import plain
from pkwbus.notation.yamlfile import YamlError, load_yaml
from pkwbus.protocol.values.notation import parse_parameter

__all__ = [
    "ActiveAlarm",
    "Alarm",
    "AlarmDecoder",
    "AlarmTable",
    "CodeTable",
    "Kind",
    "WordTable",
    "alarm_table",
]

Kind = Literal["alarm", "warning", "status"]


@dataclass(frozen=True, slots=True)
class Alarm:
    """One active alarm or warning: its code (the drive's, or the word's bit), its text
    (empty where no source explains it), and which parameter told it."""

    code: str
    text: str
    kind: Kind
    parameter: str

    @property
    def shown(self) -> str:
        return f"{self.code} {self.text}" if self.text else self.code


@dataclass(frozen=True, slots=True)
class ActiveAlarm:
    alarm: Alarm
    since: float  # wall clock, seconds: the reading that first showed it


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class WordTable(_Strict):
    """A bit word: each set bit one alarm (or warning, or status)."""

    parameter: str
    kind: Kind
    source: str
    bits: dict[int, str]
    # How a bit's code is written: {parameter}, {bit}; e.g. "16-90.{bit}".
    code: str = "{parameter} bit {bit}"
    polled: bool = True  # polled by default where the configuration does not poll it

    @model_validator(mode="after")
    def _bits(self) -> Self:
        if any(not 0 <= b <= 31 for b in self.bits):
            raise ValueError("bits are 0-31")
        parse_parameter(self.parameter)
        return self

    def decode(self, value: int) -> tuple[Alarm, ...]:
        """The alarms of the bits set in ``value``, lowest bit first."""
        return tuple(
            Alarm(self.code.format(parameter=self.parameter, bit=bit), self.bits.get(bit, ""),
                  self.kind, self.parameter)
            for bit in range(32)
            if value >> bit & 1
        )  # fmt: skip


class CodeTable(_Strict):
    """Numbers: a non-zero value is a fault or alarm number."""

    parameter: str
    kind: Kind
    source: str
    texts: dict[int, str]
    code: str = "{n}"  # e.g. "F{n:05d}" (SINAMICS r0947 7801 is F07801)
    active: bool = True  # the parameter holds what is active now (else: a log)
    polled: bool = True  # polled by default (its first element) where none is configured

    @model_validator(mode="after")
    def _parameter(self) -> Self:
        parse_parameter(self.parameter)
        return self

    def decode(self, value: int) -> tuple[Alarm, ...]:
        if not value:
            return ()
        code = self.code.format(n=value)
        return (Alarm(code, self.texts.get(value, ""), self.kind, self.parameter),)


AlarmDecoder = WordTable | CodeTable  # how one parameter's value is told in words


class AlarmTable(_Strict):
    catalog: str
    sources: dict[str, str]
    words: list[WordTable] = []
    codes: list[CodeTable] = []

    @model_validator(mode="after")
    def _sourced(self) -> Self:
        entries: list[WordTable | CodeTable] = [*self.words, *self.codes]
        for entry in entries:
            if entry.source not in self.sources:
                raise ValueError(f"{entry.parameter}: source {entry.source!r} is not in sources")
        return self

    def decoder(self, pnu: int) -> AlarmDecoder | None:
        """How a value of ``pnu`` is told in words (None: it is no alarm parameter)."""
        entries: list[WordTable | CodeTable] = [*self.words, *self.codes]
        for entry in entries:
            if parse_parameter(entry.parameter).pnu == pnu:
                return entry
        return None


@functools.cache
def alarm_table(catalog: str) -> AlarmTable | None:
    """The alarm table shipped with ``catalog``; None where there is none."""
    path = resources.files("pkwbus.catalog").joinpath("data", "alarms", f"{catalog}.yaml")
    if not path.is_file():
        return None
    try:
        data = load_yaml(path.read_text(encoding="utf-8"))
        return AlarmTable.model_validate(data)
    except YamlError as exc:
        raise CatalogError(f"alarm table {catalog}: {exc}") from None
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise CatalogError(f"alarm table {catalog}: {where}: {plain(first)}") from None
