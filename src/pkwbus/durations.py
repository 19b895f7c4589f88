"""Durations as people write them: ``250ms``, ``1s``, ``5m``, ``1h`` or plain seconds."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Final

_DURATION = re.compile(
    r"^\s*([-+]?(?:[0-9]{1,12}(?:\.[0-9]{0,12})?|\.[0-9]{1,12}))\s*(ms|s|min|m|h)?\s*$"
)
_UNITS: Final[Mapping[str | None, float]] = {
    "ms": 0.001,
    "s": 1.0,
    "m": 60.0,
    "min": 60.0,
    "h": 3600.0,
    None: 1.0,
}
HINT: Final = "write 250ms, 1s, 5m, 1h or plain seconds"


def _shown(value: object) -> str:
    """A scalar's repr (shortened); for anything else, what kind of thing it is."""
    if isinstance(value, list | tuple):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def parse_duration(value: object, *, allow_zero: bool = False) -> float:
    """Seconds; above 0 (or at least 0 with ``allow_zero``); ValueError otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise ValueError(f"{_shown(value)} is not a duration: {HINT}")
    if isinstance(value, str):
        found = _DURATION.match(value)
        if found is None:
            raise ValueError(f"{_shown(value)} is not a duration: {HINT}")
        seconds = float(found[1]) * _UNITS[found[2]]
    else:
        try:
            seconds = float(value)
        except OverflowError:
            seconds = math.inf
    if not math.isfinite(seconds) or seconds < 0 or (seconds == 0 and not allow_zero):
        floor = "0 or more" if allow_zero else "above 0"
        raise ValueError(f"{_shown(value)} is not a duration {floor}: {HINT}")
    return seconds
