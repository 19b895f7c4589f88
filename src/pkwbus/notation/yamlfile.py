"""Reading YAML safely: one error type for every way a text can fail.

Safe loading only (no Python objects), a key written twice in a mapping is
an error, and PyYAML's own failures on hostile input (impossible dates,
integers of thousands of digits, deep nesting, unhashable keys) come out as
:class:`YamlError` with the line and column where PyYAML knows them.
"""

from __future__ import annotations

from typing import Any

import yaml

from pkwbus.errors import PkwbusError

__all__ = ["UniqueKeyLoader", "YamlError", "load_yaml"]


class YamlError(PkwbusError, ValueError):
    """Text that is not YAML pkwbus can read; the message says where and why."""


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key given twice in one mapping, or a key that is no value."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, yaml.Mark] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=deep)
            try:
                first = seen.setdefault(key, key_node.start_mark)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    "found a key that is not a plain value",
                    key_node.start_mark,
                ) from None
            if first is not key_node.start_mark:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping",
                    node.start_mark,
                    f"found duplicate key {_shown(key)} (first at line {first.line + 1})",
                    key_node.start_mark,
                )
        return super().construct_mapping(node, deep=deep)


def load_yaml(text: str) -> Any:
    """The document in ``text``; :class:`YamlError` for anything it cannot be."""
    try:
        return yaml.load(text, Loader=UniqueKeyLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise YamlError(f"{where}{exc.problem or exc.context or 'not valid YAML'}") from None
    except (yaml.YAMLError, ValueError, OverflowError, TypeError) as exc:
        raise YamlError(f"not valid YAML: {exc}") from None
    except RecursionError:
        raise YamlError("the file nests too deeply") from None
