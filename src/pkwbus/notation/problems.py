"""Validation problems in plain words, shared by the configuration and the catalogs.

:func:`place` writes a pydantic location as ``lines[0].drives[2].address``,
:func:`plain` a pydantic error as a sentence (``must be a whole number, not
2.5``; ``is not a known setting; did you mean poll?``), :func:`short` and
:func:`kind` a value as a problem shows it. Nothing here raises.
"""

from __future__ import annotations

import difflib
import re
import types
import typing
from collections.abc import Mapping, Sequence
from typing import Any, Final

from pydantic import BaseModel

__all__ = ["kind", "place", "plain", "short"]


def short(value: object) -> str:
    """A value as shown in a problem: a scalar's repr (shortened), else its kind."""
    if not isinstance(value, str | int | float | bool | None):
        return kind(value)
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def kind(value: object) -> str:
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, str):
        return "text"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, int | float):
        return "a number"
    return f"a {type(value).__name__}"


_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def place(loc: Sequence[int | str]) -> str:
    """``('lines', 0, 'drives', 2, 'address')`` as ``lines[0].drives[2].address``."""
    text = ""
    previous: int | str = ""
    for item in loc:
        if item == "[key]":
            continue
        if isinstance(item, int) or previous == "parameters":
            text += f"[{item}]"
        elif not item:
            text += "['']"
        elif _IDENT.match(item):
            text += f".{item}" if text else item
        else:
            text += f"[{item}]"
        previous = item
    return text


_WORDS: Final = {
    "missing": "is required",
    "string_type": "must be text",
    "int_type": "must be a whole number",
    "int_parsing": "must be a whole number",
    "int_from_float": "must be a whole number",
    "float_type": "must be a number",
    "bool_type": "must be true or false",
    "list_type": "must be a list",
    "dict_type": "must be a mapping (key: value)",
    "model_type": "must be a mapping (key: value)",
    "model_attributes_type": "must be a mapping (key: value)",
    "string_pattern_mismatch": "may contain only letters, digits and _ . -",
    "string_too_short": "must not be empty",
    "string_too_long": "is too long",
    "too_short": "must not be empty",
    "recursion_loop": "refers to itself",
}
_SCALAR = (str, int, float, bool, type(None))
_NO_INPUT: Final = frozenset({"missing", "too_short", "string_too_short", "string_too_long"})
_BOUNDS: Final = {
    "greater_than_equal": "must be {ge} or more",
    "greater_than": "must be more than {gt}",
    "less_than_equal": "must be {le} or less",
    "less_than": "must be less than {lt}",
}


def plain(error: Mapping[str, Any], root: type[BaseModel] | None = None) -> str:
    """A pydantic error's message in plain words; ``root`` (the model validated)
    lets an unknown key be answered with the known ones."""
    error_type = error["type"]
    if error_type == "extra_forbidden":
        return _unknown_setting(error["loc"], root)
    if error_type in ("value_error", "assertion_error"):
        return str(error["msg"]).removeprefix("Value error, ").removeprefix("Assertion failed, ")
    if error_type in _BOUNDS:
        bound = _BOUNDS[error_type].format(**error.get("ctx", {}))
        return f"{bound}, not {short(error.get('input'))}"
    message = _WORDS.get(error_type) or str(error["msg"]).replace("Input should be", "must be")
    if error_type in _NO_INPUT:
        return message
    value = error.get("input")
    return f"{message}, not {short(value) if isinstance(value, _SCALAR) else kind(value)}"


def _unknown_setting(loc: Sequence[int | str], root: type[BaseModel] | None) -> str:
    known = _known_keys(loc[:-1], root) if root is not None else []
    if not known:
        return "is not a known setting"
    close = difflib.get_close_matches(str(loc[-1]), known, n=1)
    if close:
        return f"is not a known setting; did you mean {close[0]}?"
    return f"is not a known setting (known: {', '.join(known)})"


def _known_keys(loc: Sequence[int | str], root: type[BaseModel]) -> list[str]:
    model = root
    for item in loc:
        if isinstance(item, str) and item in model.model_fields:
            inner = _model_in(model.model_fields[item].annotation)
            if inner is None:
                return []
            model = inner
    return [name for name, info in model.model_fields.items() if not info.exclude]


def _model_in(annotation: object) -> type[BaseModel] | None:
    """The model class inside ``list[X]``, ``dict[K, X]``, ``X | None``, ``Annotated[X, ...]``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    origin = typing.get_origin(annotation)
    if origin is None and not isinstance(annotation, types.UnionType):
        return None
    for arg in reversed(typing.get_args(annotation)):
        found = _model_in(arg)
        if found is not None:
            return found
    return None
