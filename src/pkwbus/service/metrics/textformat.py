"""The pieces of the Prometheus text format (version 0.0.4) a series is rendered from:
a value as Go prints it, the text before a value, a family's ``# HELP`` and ``# TYPE``
lines; each the text ``prometheus_client.generate_latest`` makes."""

from __future__ import annotations

import math
from collections.abc import Mapping

__all__ = ["format_value", "head", "header", "same_number"]

_SPECIAL = {"inf": "+Inf", "-inf": "-Inf", "nan": "NaN"}


def format_value(value: float) -> str:
    """A sample value as Go prints it: the text of ``prometheus_client.utils.floatToGoString``."""
    text = repr(float(value))
    dot = text.find(".")
    if dot < 0:  # inf, nan, or an exponent: 1e+16
        return _SPECIAL.get(text, text)
    if dot > 6 and text[0] != "-":  # seven digits before the point: an exponent, as in Go
        mantissa = f"{text[0]}.{text[1:dot]}{text[dot + 1 :]}".rstrip("0.")
        return f"{mantissa}e+{dot - 1:02d}"
    return text


def same_number(old: float | str, value: float) -> bool:
    """Whether ``old`` prints as ``value`` does: a number equal to it and of the same
    sign (-0.0 is printed as such, though it equals 0.0); never a text, never NaN."""
    if isinstance(old, str):
        return False
    number = float(old)
    return number == value and math.copysign(1.0, number) == math.copysign(1.0, value)


def _escape(value: str) -> str:
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")


def head(name: str, labels: Mapping[str, str]) -> str:
    """The text of a sample line before its value: ``name{a="x",b="y"} ``."""
    if not labels:
        return f"{name} "
    inner = ",".join(f'{k}="{_escape(v)}"' for k, v in sorted(labels.items()))
    return f"{name}{{{inner}}} "


def header(name: str, documentation: str, kind: str) -> str:
    """The ``# HELP`` and ``# TYPE`` lines of a family."""
    doc = documentation.replace("\\", r"\\").replace("\n", r"\n")
    return f"# HELP {name} {doc}\n# TYPE {name} {kind}\n"
