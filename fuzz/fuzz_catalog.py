"""Fuzz the catalog loader with random YAML text.

Property: _parse_catalog (what load_catalog_file runs on a file's text)
raises nothing but CatalogError, whatever the text.

Run: .venv/bin/python fuzz/fuzz_catalog.py -max_total_time=60 -timeout=10 var/fuzz/catalog
"""

from __future__ import annotations

import sys
from importlib import resources

import atheris

with atheris.instrument_imports(include=["yaml", "pkwbus"]):
    import yaml  # noqa: F401  (instrumented so the fuzzer sees the parser's branches)

    from pkwbus.catalog.loader import CatalogError, _parse_catalog

import _support

# Every finding of these harnesses (see docs/fuzzing.md) is fixed; a new one
# would be listed here while it is open.
KNOWN: tuple[_support.Known, ...] = ()


def test_one_input(data: bytes) -> None:
    text = data.decode("utf-8", errors="replace")
    try:
        _parse_catalog(text, "fuzz.yaml")
    except CatalogError:
        pass
    except Exception as exc:
        _support.tolerate(exc, KNOWN)


def seeds() -> list[bytes]:
    data = resources.files("pkwbus.catalog").joinpath("data")
    # The built-in catalogs, cut into pieces of a few entries: small inputs run faster.
    out = []
    for path in data.iterdir():
        if path.name.endswith(".yaml"):
            lines = path.read_bytes().splitlines(keepends=True)
            head = next(n for n, line in enumerate(lines) if line.startswith(b"parameters:"))
            out.append(b"".join(lines[: min(head + 1, 12)]))
            for start in range(head + 1, len(lines), 20):
                out.append(
                    b"name: x\ndialect: uss\nparameters:\n" + b"".join(lines[start : start + 20])
                )
    out.append(
        b"name: t\ndialect: fc\nsources: {s: x}\nparameters:\n"
        b"  16-13: {name: f, type: u16, conversion: -1, unit: Hz, min: 0, max: 10, source: s}\n"
    )
    return out


def main() -> None:
    _support.write_seeds(seeds())
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
