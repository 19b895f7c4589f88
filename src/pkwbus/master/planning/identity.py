"""What identifies a drive's model and software, and the descriptions known for each.

A drive's description of its parameters depends on its model and software
version, not on its address: drives of one kind describe alike, and a drive
replaced by another model must be described afresh. The identity is read
over the parameter channel before the descriptions:

- Danfoss FC: 15-40 "FC Type" and 15-43 "Software Version", texts (Danfoss
  FC 100 Design Guide, RS-485 chapter: "15-40 FC Type to 15-53 Power Card
  Serial Number contain data type 9");
- Siemens USS and PROFIdrive: r0964 "Device identification", indexes 0
  (company), 1 (device type) and 2 (firmware version) (SINAMICS G120 List
  Manual, r0964).

Other dialects have no identity here: their drives are described at every
start. :class:`DescriptionBook` keeps the descriptions by identity; the
service keeps it in a file (:meth:`DescriptionBook.to_json`). Pure: no I/O.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Final

from pkwbus.master.planning.outcomes import Answered, Outcome, Rejected
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import DriveDescription
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.values.types import CONVERSION_FACTORS

__all__ = ["DescriptionBook", "identity_of", "identity_requests"]

# Dialect -> (PNU, index, text) of each identity parameter.
_IDENTITY: Final[Mapping[str, tuple[tuple[int, int | None, bool], ...]]] = {
    "fc": ((1540, None, True), (1543, None, True)),
    "uss": ((964, 0, False), (964, 1, False), (964, 2, False)),
    "profidrive": ((964, 0, False), (964, 1, False), (964, 2, False)),
}
_FIELDS: Final = tuple(f.name for f in dataclasses.fields(DriveDescription))
FORMAT: Final = 1  # of the book's file: another format is read as no book


def identity_requests(dialect: Dialect, *, texts: bool = True) -> tuple[pkw.PkwRequest, ...]:
    """The reads that identify a drive of ``dialect``; none where it has no identity here
    (or where it is told by texts that cannot be sent: a PPO's four PKW words)."""
    found = _IDENTITY.get(dialect.name, ())
    if not texts and any(text for _, _, text in found):
        return ()
    return tuple(pkw.read_parameter(dialect, pnu, index, text=text) for pnu, index, text in found)


def identity_of(dialect: Dialect, outcomes: Sequence[Outcome]) -> str | None:
    """The identity the answers to :func:`identity_requests` tell; None when they tell
    nothing (every read refused or unanswered)."""
    parts = []
    for outcome in outcomes:
        if isinstance(outcome, Answered) and isinstance(outcome.response, pkw.TextResponse):
            parts.append(outcome.response.text.decode("latin-1").strip("\x00 "))
        elif isinstance(outcome, Answered) and isinstance(outcome.response, pkw.ValueResponse):
            parts.append(str(outcome.response.raw))
        elif isinstance(outcome, Rejected):
            parts.append("-")
        else:
            return None
    if not parts or all(p == "-" for p in parts):
        return None
    return f"{dialect.name}:" + "|".join(parts)


class DescriptionBook:
    """Descriptions by drive identity and PNU; None where the drive has none (it refuses
    AK 4 for that parameter). Shared by the drives of every line.

    A drive that starts describing a parameter claims it for its identity
    (:meth:`claim`): the other drives of that kind wait for its answer instead
    of asking the same, until it releases the claim (described, given up, or
    away).
    """

    def __init__(self) -> None:
        # identity -> PNU -> (its description, the elements read of it)
        self.entries: dict[str, dict[int, tuple[DriveDescription, frozenset[int]]]] = {}
        self._claims: dict[tuple[str, int], object] = {}

    def get(self, identity: str, pnu: int, elements: Iterable[int] = ()) -> DriveDescription | None:
        """How drives of ``identity`` describe ``pnu``, when the elements read of it cover
        ``elements`` (a parameter described for polling lacks the limits a write needs)."""
        found = self.entries.get(identity, {}).get(pnu)
        if found is None or not set(elements) <= found[1]:
            return None
        return found[0]

    def put(
        self, identity: str, pnu: int, description: DriveDescription, elements: Iterable[int]
    ) -> None:
        self.entries.setdefault(identity, {})[pnu] = (description, frozenset(elements))

    def claim(self, identity: str, pnu: int, owner: object) -> bool:
        """Whether ``owner`` may describe ``pnu`` for drives of ``identity`` (it holds the
        claim now), or another drive of that kind is describing it."""
        holder = self._claims.setdefault((identity, pnu), owner)
        return holder is owner

    def release(self, owner: object, pnu: int | None = None) -> None:
        """``owner``'s claims (of ``pnu``, or all) end."""
        for key in [k for k, held in self._claims.items() if held is owner]:
            if pnu is None or key[1] == pnu:
                del self._claims[key]

    def to_json(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "drives": {
                identity: {
                    str(pnu): {"elements": sorted(read), "description": dataclasses.asdict(d)}
                    for pnu, (d, read) in found.items()
                }
                for identity, found in self.entries.items()
            },
        }

    @classmethod
    def from_json(cls, data: object) -> DescriptionBook:
        """The book a :meth:`to_json` made; ValueError for anything else."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f"not a book of drive descriptions of format {FORMAT}")
        drives = data.get("drives")
        if not isinstance(drives, dict):
            raise ValueError("no mapping of drive identities")
        book = cls()
        for identity, found in drives.items():
            if not isinstance(identity, str) or not isinstance(found, dict):
                raise ValueError(f"entry {identity!r} is not a mapping of parameters")
            for pnu, entry in found.items():
                if not isinstance(entry, dict) or set(entry) != {"elements", "description"}:
                    raise ValueError(f"{identity} {pnu}: not an entry of a description")
                read = entry["elements"]
                if not isinstance(read, list) or not all(type(e) is int for e in read):
                    raise ValueError(f"{identity} {pnu}: elements {read!r} are not numbers")
                book.put(identity, int(pnu), _description(entry["description"]), read)
        return book


def _description(data: object) -> DriveDescription:
    """A description as :meth:`DescriptionBook.to_json` wrote it; ValueError for anything
    else (a file may have been edited: nothing in it is trusted)."""
    if not isinstance(data, dict) or set(data) != set(_FIELDS):
        raise ValueError(f"not a description: {data!r}")
    for key in ("type_code", "array", "conversion"):
        value = data[key]
        if value is not None and type(value) is not int:
            raise ValueError(f"{key}: {value!r} is not a whole number")
    for key in ("low_raw", "high_raw"):
        value = data[key]
        if value is not None and (type(value) not in (int, float) or not math.isfinite(value)):
            raise ValueError(f"{key}: {value!r} is not a finite number")
    if not isinstance(data["name"], str) or not isinstance(data["unit"], str | None):
        raise ValueError("name and unit must be texts")
    if data["read_only"] is not None and type(data["read_only"]) is not bool:
        raise ValueError("read_only must be true, false or null")
    conversion, array, code = data["conversion"], data["array"], data["type_code"]
    if conversion is not None and conversion not in CONVERSION_FACTORS:
        raise ValueError(f"conversion index {conversion!r} is not one pkwbus knows")
    if array is not None and array < 1:
        raise ValueError(f"array of {array} elements")
    if code is not None and not 0 <= code <= 0xFF:
        raise ValueError(f"data type {code} is not a byte")
    return DriveDescription(**data)
