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
from collections.abc import Mapping, Sequence
from typing import Any, Final

from pkwbus.master.outcomes import Answered, Outcome, Rejected
from pkwbus.protocol import pkw
from pkwbus.protocol.descriptions import DriveDescription
from pkwbus.protocol.dialects import Dialect
from pkwbus.protocol.value_types import CONVERSION_FACTORS

__all__ = ["DescriptionBook", "identity_of", "identity_requests"]

# Dialect -> (PNU, index, text) of each identity parameter.
_IDENTITY: Final[Mapping[str, tuple[tuple[int, int | None, bool], ...]]] = {
    "fc": ((1540, None, True), (1543, None, True)),
    "uss": ((964, 0, False), (964, 1, False), (964, 2, False)),
    "profidrive": ((964, 0, False), (964, 1, False), (964, 2, False)),
}
_FIELDS: Final = tuple(f.name for f in dataclasses.fields(DriveDescription))


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

    def __init__(self, entries: Mapping[str, Mapping[int, DriveDescription | None]] = {}) -> None:
        self.entries: dict[str, dict[int, DriveDescription | None]] = {
            identity: dict(found) for identity, found in entries.items()
        }
        self._claims: dict[tuple[str, int], object] = {}

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

    def get(self, identity: str, pnu: int) -> tuple[bool, DriveDescription | None]:
        """(whether it is known, the description) of ``pnu`` on drives of ``identity``."""
        found = self.entries.get(identity, {})
        return pnu in found, found.get(pnu)

    def put(self, identity: str, pnu: int, description: DriveDescription | None) -> None:
        self.entries.setdefault(identity, {})[pnu] = description

    def to_json(self) -> dict[str, Any]:
        return {
            identity: {
                str(pnu): None if d is None else dataclasses.asdict(d) for pnu, d in found.items()
            }
            for identity, found in self.entries.items()
        }

    @classmethod
    def from_json(cls, data: object) -> DescriptionBook:
        """The book a :meth:`to_json` made; ValueError for anything else."""
        if not isinstance(data, dict):
            raise ValueError("not a mapping of drive identities")
        entries: dict[str, dict[int, DriveDescription | None]] = {}
        for identity, found in data.items():
            if not isinstance(identity, str) or not isinstance(found, dict):
                raise ValueError(f"entry {identity!r} is not a mapping of parameters")
            entries[identity] = {int(pnu): _description(d) for pnu, d in found.items()}
        return cls(entries)


def _description(data: object) -> DriveDescription | None:
    if data is None:
        return None
    if not isinstance(data, dict) or set(data) != set(_FIELDS):
        raise ValueError(f"not a description: {data!r}")
    checks = {"unit": (str, type(None)), "name": (str,), "read_only": (bool, type(None))}
    for key, value in data.items():
        allowed = checks.get(key, (int, float, type(None)))
        if (isinstance(value, bool) and key != "read_only") or not isinstance(value, allowed):
            raise ValueError(f"{key}: {value!r} is not a description's value")
    conversion = data["conversion"]
    if conversion is not None and conversion not in CONVERSION_FACTORS:
        raise ValueError(f"conversion index {conversion!r} is not one pkwbus knows")
    return DriveDescription(**data)
