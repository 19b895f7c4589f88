"""Parameter catalogs: names, types, scaling, units and limits of drive parameters."""

from types import MappingProxyType
from typing import Final

from pkwbus.catalog.description import ParameterDescription, Value
from pkwbus.catalog.loader import (
    CONVERSION_INDEXES,
    Catalog,
    CatalogError,
    Dialect,
    ParameterSpec,
    ValueType,
    available_catalogs,
    load_catalog,
    load_catalog_file,
)

#: The catalog used for a protocol ("fc", "uss") when none is named: by
#: ``pkwbus read``/``write``/``describe`` to decode, by ``pkwbus simulate`` to serve.
DEFAULT_CATALOGS: Final = MappingProxyType({"fc": "danfoss-fc", "uss": "siemens-g120"})

__all__ = [
    "CONVERSION_INDEXES",
    "DEFAULT_CATALOGS",
    "Catalog",
    "CatalogError",
    "Dialect",
    "ParameterDescription",
    "ParameterSpec",
    "Value",
    "ValueType",
    "available_catalogs",
    "load_catalog",
    "load_catalog_file",
]
