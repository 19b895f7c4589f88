"""Reading a configuration file: every problem ends in one :class:`ConfigError`."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import (
    ValidationError,
)

from pkwbus.notation.problems import kind
from pkwbus.notation.yamlfile import YamlError, load_yaml
from pkwbus.service.config.base import LISTEN_ENV, MAX_CONFIG_BYTES, ConfigError, placed
from pkwbus.service.config.catalogs import Catalogs, builtin_catalogs
from pkwbus.service.config.model import Config

__all__ = ["load_config", "parse_config"]


def load_config(
    path: str | os.PathLike[str],
    *,
    environ: Mapping[str, str] | None = None,
    catalogs: Catalogs | None = None,
) -> Config:
    """Read and check a configuration file; :class:`ConfigError` for any problem."""
    shown = os.fspath(path)
    try:
        with Path(path).open("rb") as file:  # a device or a pipe too, but never more than the cap
            data = file.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError([f"{shown}: cannot read: {exc.strerror or exc}"]) from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(
            [f"{shown}: larger than {MAX_CONFIG_BYTES >> 20} MiB: not a pkwbus configuration"]
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError([f"{shown}: not UTF-8 text (byte {exc.start})"]) from None
    return parse_config(text, environ=environ, catalogs=catalogs, base=Path(path).parent)


def parse_config(
    text: str,
    *,
    environ: Mapping[str, str] | None = None,
    catalogs: Catalogs | None = None,
    base: Path | None = None,
) -> Config:
    """Check configuration text (what :func:`load_config` does after reading the file)."""
    data = _parse_yaml(text)
    env = os.environ if environ is None else environ
    listen = env.get(LISTEN_ENV)
    if listen:
        data = {**data, "listen": listen}
    # ``base``: the configuration file's folder, where relative GSD paths start.
    context = {"catalogs": catalogs or builtin_catalogs(), "base": base}
    try:
        return Config.model_validate(data, context=context)
    except ValidationError as exc:
        raise ConfigError(_problems(exc, listen_from_env=bool(listen))) from None
    except RecursionError:
        raise ConfigError(["the file nests too deeply"]) from None


def _parse_yaml(text: str) -> dict[str, Any]:
    try:
        data = load_yaml(text)
    except YamlError as exc:
        raise ConfigError([str(exc)]) from None
    if data is None:
        raise ConfigError(["the file is empty: it needs at least lines:"])
    if not isinstance(data, dict):
        raise ConfigError([f"the top level must be a mapping (key: value), not {kind(data)}"])
    return data


def _problems(exc: ValidationError, *, listen_from_env: bool) -> list[str]:
    out: list[str] = []
    for where, message in placed(exc.errors(include_url=False), Config):
        if listen_from_env and where.startswith("listen"):
            where = f"{LISTEN_ENV} (overrides listen)"
        out.append(f"{where or 'config'}: {message}")
    return out
