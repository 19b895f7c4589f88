"""A value as people read it on the status page: to its resolution, not to a float's digits.

A scaled integer shows the decimals its scaling gives (a conversion index of -2:
two decimals, Danfoss FC protocol, conversion index); a float, or a scaling
that is no power of ten, about four significant digits; an enumeration's
number, its text from the catalog with it ("English [0]"). The API's ``value``
and ``/metrics`` keep full precision: this is presentation only.

A counter the drive keeps of its own life in a unit of time (the catalog's
``counter`` with a unit, or an element unit, of ms, s, min, h or d) reads as a
duration, in its own units: to the hour where it counts hours ("13 h" for
Danfoss 15-00 Operating hours, whose value is 46800 s: raw hours, conversion
index 74), in days where it counts days ("12 d", SINAMICS r2114[1]), and as
"h:mm:ss" where it counts finer within a day ("3:25:45", r2114[0] in ms; above
a day, hours to a tenth). That text names its unit: the unit beside the value
(the API's ``unit``, s for 15-00) is not to be added to it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from fractions import Fraction
from typing import Final

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.protocol.values import ValueType

__all__ = ["SIGNIFICANT", "TIME_UNITS", "duration", "readable", "time_unit"]

SIGNIFICANT = 4  # digits a float (or an odd scaling) is shown with

#: The units of time a counter may count in, in seconds.
TIME_UNITS: Final[Mapping[str, Fraction]] = {
    "ms": Fraction(1, 1000),
    "s": Fraction(1),
    "min": Fraction(60),
    "h": Fraction(3600),
    "d": Fraction(86400),
}
_HOUR: Final = 3600
_DAY: Final = 86400


@functools.lru_cache(maxsize=256)
def _decimals_of(factor: Fraction) -> int | None:
    """k when ``factor`` is 10**-k (k >= 0), else None (kept: a catalog has few scalings)."""
    k = 0
    while factor < 1 and k < 9:
        factor *= 10
        k += 1
    return k if factor == 1 else None


def _significant(value: float) -> str:
    if value == 0 or not math.isfinite(value):
        return f"{value:g}"
    decimals = max(0, SIGNIFICANT - 1 - math.floor(math.log10(abs(value))))
    return f"{value:.{decimals}f}"


def time_unit(fmt: ParameterDescription) -> str:
    """The unit of time a counter of ``fmt`` counts in (its unit, else its element's);
    empty where it is no counter or counts no time."""
    if not fmt.counter:
        return ""
    unit = fmt.unit or fmt.element_unit
    return unit if unit in TIME_UNITS else ""


def _count(amount: float, unit: str) -> str:
    """Whole units with thousands separated ("1,234 h"), else to a tenth ("12.5 h")."""
    if amount == round(amount):
        return f"{round(amount):,} {unit}"
    return f"{amount:,.1f} {unit}"


def duration(value: float, unit: str, step: Fraction = Fraction(1)) -> str | None:
    """``value`` in ``unit`` (one of :data:`TIME_UNITS`) as people read a duration: in
    days where it counts days (``step``, the value's resolution in ``unit``, is a day or
    more), in hours where it counts hours, else as h:mm:ss within a day and in hours to
    a tenth above one. None for what is no duration (negative, not finite)."""
    if not math.isfinite(value) or value < 0:
        return None
    per_unit = TIME_UNITS[unit]
    seconds = float(value * per_unit) if isinstance(value, float) else value * per_unit
    resolution = step * per_unit
    if resolution >= _DAY:
        return _count(float(seconds / _DAY), "d")
    if resolution >= _HOUR:
        return _count(float(seconds / _HOUR), "h")
    if seconds >= _DAY:
        return f"{float(seconds) / _HOUR:,.1f} h"
    whole = math.floor(seconds)  # as a clock shows it: the seconds begun are not yet counted
    hours, rest = divmod(whole, _HOUR)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}"


def readable(value: Value, fmt: ParameterDescription) -> str:
    """``value`` as the status page shows it: without its unit, but for a duration (a
    counter of time), which names its own."""
    if isinstance(value, str):
        return value
    if fmt.enumerates and isinstance(value, int):
        option = fmt.option(value)  # an enumeration: its text with the number
        return f"{option} [{value}]" if option else f"{value}"
    unit = time_unit(fmt)
    if unit:
        told = duration(value, unit, fmt.scaling.factor)
        if told is not None:
            return told
    if fmt.vtype is ValueType.F32 or (isinstance(value, float) and fmt.vtype is None):
        return _significant(float(value))
    decimals = _decimals_of(fmt.scaling.factor)
    if decimals is None:
        return _significant(float(value))
    return f"{float(value):.{decimals}f}" if decimals else f"{round(value)}"
