"""Parameter catalogs: names, types, scaling, units and limits of drive parameters."""

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

__all__ = [
    "CONVERSION_INDEXES",
    "Catalog",
    "CatalogError",
    "Dialect",
    "ParameterSpec",
    "ValueType",
    "available_catalogs",
    "load_catalog",
    "load_catalog_file",
]
