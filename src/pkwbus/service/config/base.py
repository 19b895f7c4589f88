"""What every part of the configuration shares: its error, its base model, a problem's place.

Raises nothing itself; :class:`ConfigError` is what the loading functions raise.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Final

from pydantic import (
    BaseModel,
    ConfigDict,
)
from pydantic_core import ErrorDetails, PydanticCustomError

from pkwbus.errors import PkwbusError
from pkwbus.notation.problems import place, plain
from pkwbus.protocol.buses import DIALECTS_BY_PROTOCOL, USS_MAX_ADDRESS, Bus

__all__ = [
    "DEFAULT_LISTEN",
    "DEFAULT_TOKEN_ENV",
    "DIALECTS_BY_PROTOCOL",
    "LISTEN_ENV",
    "MAX_CONFIG_BYTES",
    "MAX_HTTP_CONNECTIONS",
    "PORT_SCHEMES",
    "USS_MAX_ADDRESS",
    "ConfigError",
    "Model",
    "Place",
    "fail",
    "only",
    "placed",
]


DEFAULT_LISTEN: Final = "127.0.0.1:9725"
LISTEN_ENV: Final = "PKWBUS_LISTEN"
DEFAULT_TOKEN_ENV: Final = "PKWBUS_WRITE_TOKEN"
PORT_SCHEMES: Final = frozenset({"socket", "rfc2217", "loop", "spy", "alt", "hwgrep", "sim"})
MAX_CONFIG_BYTES: Final = 1024 * 1024  # a configuration file is read up to this, no further


# HTTP connections at most: with the ports, the audit database and the listener
# every descriptor stays below 1024, which pyserial's socket:// handler needs (it
# waits with select()).
MAX_HTTP_CONNECTIONS = 900


class ConfigError(PkwbusError):
    """The configuration cannot be used; ``problems`` has one line per problem."""

    def __init__(self, problems: Sequence[str]) -> None:
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


Place = tuple[str, str]  # (place relative to the model that found it, message)


def fail(problems: Sequence[Place]) -> PydanticCustomError:
    """One validation error carrying several problems, each with its own place."""
    summary = "; ".join(f"{p}: {m}" if p else m for p, m in problems)
    return PydanticCustomError(
        "pkwbus_problems", "{summary}", {"summary": summary, "problems": list(problems)}
    )


def placed(errors: Iterable[ErrorDetails], root: type[BaseModel]) -> list[Place]:
    """A validation's problems in plain words, each with its place relative to ``root``
    (the model validated there, whose settings an unknown key is answered with)."""
    out: list[Place] = []
    for error in errors:
        where = place(error["loc"])
        if error["type"] == "pkwbus_problems":
            for inner, message in error.get("ctx", {}).get("problems", []):
                out.append((f"{where}.{inner}" if where and inner else where or inner, message))
        else:
            out.append((where, plain(error, root)))
    return out


def only(protocol: Bus, *keys: str, why: str = "") -> dict[str, str]:
    """What a user who gives one of ``keys``, settings of ``protocol``'s lines or drives,
    on another bus's is told."""
    told = f"applies to protocol {protocol} only" + (f": {why}" if why else "")
    return dict.fromkeys(keys, told)


class Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
