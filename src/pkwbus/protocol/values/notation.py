"""Parameter notation: ``16-13``, ``1613``, ``r0021``, ``P7841[2]``, and each drive's one name.

Notation (everywhere: CLI, config, API, catalogs): ``16-13`` and ``3-41``
(Danfoss group-number style: PNU 1613, 341), ``1613`` (plain PNU), ``r0021``,
``p1082``, ``P7841`` (Siemens style, case-insensitive), each optionally with
an index: ``P7841[2]``.

Each drive has one name per parameter (:func:`canonical`): a drive whose
dialect numbers parameters the Danfoss way calls PNU 341 ``3-41`` whether it
was written ``341``, ``0341`` or ``03-41``, and refuses the Siemens ``r``/``p``
prefix; any other drive calls it ``r0021`` / ``p1082`` when the prefix is
known (from the catalog, else from the configuration), else by its plain
number.

Raises :class:`ParameterNotationError` for text that is not a parameter, or a notation
the drive does not use.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from pkwbus.protocol.errors import LocalProtocolError

__all__ = [
    "MAX_INDEX",
    "MAX_PNU",
    "ParameterNotationError",
    "ParameterRef",
    "canonical",
    "danfoss_name",
    "parse_parameter",
    "siemens_name",
]


class ParameterNotationError(LocalProtocolError):
    """Text that is not a parameter in any notation pkwbus knows."""


MAX_PNU: Final = 0xFFFF
MAX_INDEX: Final = 0xFF

_NOTATION = re.compile(
    r"""^(?:
        (?P<group>[0-9]{1,2})-(?P<number>[0-9]{2})
      | (?P<prefix>[rRpP])(?P<siemens>[0-9]{1,5})
      | (?P<plain>[0-9]{1,5})
    )(?:\[(?P<index>[0-9]{1,3})\])?$""",
    re.VERBOSE,
)
_HINT = "write it as 16-13, 1613, r0021 or P7841[2]"


@dataclass(frozen=True, slots=True)
class ParameterRef:
    """A parameter as written: its PNU, its index if one was given, and its name as written."""

    pnu: int
    index: int | None
    name: str

    def __str__(self) -> str:
        return self.name if self.index is None else f"{self.name}[{self.index}]"

    @property
    def prefix(self) -> str:
        """``r`` or ``p`` when written in Siemens style, else empty."""
        return self.name[:1].lower() if self.name[:1] in ("r", "R", "p", "P") else ""


def parse_parameter(text: str) -> ParameterRef:
    """Parse the notation; a clear :class:`ParameterNotationError` for anything else."""
    written = text.strip()
    found = _NOTATION.match(written)
    if found is None:
        raise ParameterNotationError(f"{text!r} is not a parameter: {_HINT}")
    if found["group"] is not None:
        pnu = int(found["group"] + found["number"])
        name = f"{int(found['group'])}-{found['number']}"
    elif found["siemens"] is not None:
        pnu = int(found["siemens"])
        name = found["prefix"] + found["siemens"]
    else:
        pnu = int(found["plain"])
        name = found["plain"]
    if pnu > MAX_PNU:
        raise ParameterNotationError(f"{text!r}: parameter number {pnu} is above {MAX_PNU}")
    index = None if found["index"] is None else int(found["index"])
    if index is not None and index > MAX_INDEX:
        raise ParameterNotationError(f"{text!r}: index {index} is above {MAX_INDEX}")
    return ParameterRef(pnu, index, name)


def danfoss_name(pnu: int) -> str:
    """Danfoss group-number style: 341 -> ``3-41``, 1613 -> ``16-13``, 5 -> ``0-05``."""
    return f"{pnu // 100}-{pnu % 100:02d}"


def siemens_name(prefix: str, pnu: int) -> str:
    """Siemens style with at least four digits: ``r``, 21 -> ``r0021``."""
    return f"{prefix}{pnu:04d}"


def canonical(ref: ParameterRef, *, danfoss: bool, prefix: str = "") -> ParameterRef:
    """``ref`` under the drive's one name for it.

    ``danfoss``: the drive numbers its parameters in groups (Danfoss FC): the
    name is ``3-41``, and a Siemens ``r``/``p`` prefix is a notation error
    naming that form. Otherwise ``prefix`` is the ``r``/``p`` the drive's
    catalog or configuration gives the parameter: ``r0021``; without one the
    name is the plain number (``2000``), whatever prefix was written.
    """
    if danfoss:
        name = danfoss_name(ref.pnu)
        if ref.prefix:
            written = name if ref.index is None else f"{name}[{ref.index}]"
            raise ParameterNotationError(
                f"{ref}: r/p is Siemens notation; this drive numbers its parameters "
                f"in groups: write {written}"
            )
    elif prefix:
        name = siemens_name(prefix.lower(), ref.pnu)
    else:
        name = str(ref.pnu)
    return ParameterRef(ref.pnu, ref.index, name)
