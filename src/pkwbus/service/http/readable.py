"""A value as people read it on the status page: to its resolution, not to a float's digits.

A scaled integer shows the decimals its scaling gives (a conversion index of -2:
two decimals, Danfoss FC protocol, conversion index); a float, or a scaling
that is no power of ten, about four significant digits; an enumeration's
number, its text from the catalog with it ("English [0]"). The API's ``value``
and ``/metrics`` keep full precision: this is presentation only.
"""

from __future__ import annotations

import math
from fractions import Fraction

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.protocol.values import ValueType

__all__ = ["SIGNIFICANT", "readable"]

SIGNIFICANT = 4  # digits a float (or an odd scaling) is shown with


def _decimals_of(factor: Fraction) -> int | None:
    """k when ``factor`` is 10**-k (k >= 0), else None."""
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


def readable(value: Value, fmt: ParameterDescription) -> str:
    """``value`` as the status page shows it (without its unit)."""
    if isinstance(value, str):
        return value
    if fmt.enumerates and isinstance(value, int):
        option = fmt.option(value)  # an enumeration: its text with the number
        return f"{option} [{value}]" if option else f"{value}"
    if fmt.vtype is ValueType.F32 or (isinstance(value, float) and fmt.vtype is None):
        return _significant(float(value))
    decimals = _decimals_of(fmt.scaling.factor)
    if decimals is None:
        return _significant(float(value))
    return f"{float(value):.{decimals}f}" if decimals else f"{round(value)}"
