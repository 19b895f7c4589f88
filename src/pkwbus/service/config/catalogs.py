"""Where the configuration looks catalogs up: the built-in ones, or a stand-in for tests."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

from pydantic import (
    ValidationInfo,
)

from pkwbus.catalog import CatalogError, ParameterSpec, available_catalogs, load_catalog

__all__ = ["CatalogLike", "Catalogs", "builtin_catalogs", "catalogs_of"]


class CatalogLike(Protocol):
    """What the config needs of a catalog: ``pkwbus.catalog.Catalog`` has it."""

    def get(self, pnu: int, /) -> ParameterSpec | None: ...


@dataclass(frozen=True)
class Catalogs:
    """Where catalog names are looked up: the built-in ones, or a stand-in for tests.

    ``load(name)`` returns the catalog or raises :class:`LookupError` (unknown
    name) or :class:`ValueError` (a broken catalog), each with a message.
    """

    load: Callable[[str], CatalogLike]
    available: Callable[[], Sequence[str]]


def builtin_catalogs() -> Catalogs:
    """The catalogs shipped in :mod:`pkwbus.catalog`."""

    def load(name: str) -> CatalogLike:
        if name not in available_catalogs():
            raise LookupError(f"unknown catalog {name!r}")
        try:
            return load_catalog(name)
        except CatalogError as exc:
            raise ValueError(f"catalog {name!r} cannot be loaded: {exc}") from None

    def available() -> Sequence[str]:
        return tuple(available_catalogs())

    return Catalogs(load=load, available=available)


def catalogs_of(info: ValidationInfo) -> Catalogs:
    context = info.context if isinstance(info.context, dict) else {}
    found = context.get("catalogs")
    return found if isinstance(found, Catalogs) else builtin_catalogs()
