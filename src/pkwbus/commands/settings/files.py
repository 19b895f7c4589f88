"""Backup documents (:class:`pkwbus.service.history.backup.Backup`) as files: JSON, or YAML
for a name ending in .yaml or .yml; ``-`` is stdin or stdout.

Raises :class:`~pkwbus.commands.common.CommandError` (exit 2, one line) for a file that
cannot be read or written, or that is not a backup document.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from pkwbus.commands.common import CommandError, Exit
from pkwbus.notation.yamlfile import YamlError, load_yaml
from pkwbus.service.history.backup import Backup

__all__ = ["MAX_BYTES", "check_output", "document_text", "load_backup", "write_document"]

YAML_SUFFIXES = (".yaml", ".yml")
MAX_BYTES = 4 << 20  # far above the 4096 settings a document may hold


def _is_yaml(path: str) -> bool:
    return path.lower().endswith(YAML_SUFFIXES)


def load_backup(path: str) -> Backup:
    """The backup document in ``path`` (``-``: stdin, read as YAML, which JSON is too)."""
    where = "stdin" if path == "-" else path
    try:
        if path == "-":
            text = sys.stdin.read(MAX_BYTES + 1)
        else:
            with open(path, encoding="utf-8") as file:
                text = file.read(MAX_BYTES + 1)
    except OSError as exc:
        raise CommandError(f"cannot read {where}: {exc.strerror or exc}", Exit.BAD_INPUT) from None
    except UnicodeDecodeError:
        raise _not_a_backup(where, "not UTF-8 text") from None
    if len(text) > MAX_BYTES:
        raise _not_a_backup(where, f"larger than {MAX_BYTES >> 20} MiB")
    try:
        if path == "-" or _is_yaml(path):
            data = load_yaml(text)
        else:
            data = json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise _not_a_backup(
            where, f"not JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})"
        ) from None
    except (YamlError, ValueError) as exc:
        raise _not_a_backup(where, str(exc)) from None
    try:
        return Backup.model_validate(data)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(x) for x in e['loc']) or 'the document'}: {e['msg']}"
            for e in exc.errors()[:5]
        )
        raise _not_a_backup(where, problems) from None


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number a backup holds")


def _not_a_backup(where: str, why: str) -> CommandError:
    one_line = " ".join(why.split())
    return CommandError(f"{where}: not a backup document: {one_line}", Exit.BAD_INPUT)


def document_text(document: dict[str, Any], path: str) -> str:
    """``document`` as JSON, or as YAML where ``path`` ends in .yaml or .yml."""
    if _is_yaml(path):
        return yaml.safe_dump(document, sort_keys=False, allow_unicode=True)
    return json.dumps(document, indent=2, ensure_ascii=False) + "\n"


def check_output(path: str) -> None:
    """A file can be written where ``path`` says (checked before anything is sent)."""
    if path == "-":
        return
    folder = Path(path).parent
    if not folder.is_dir() or Path(path).is_dir() or not os.access(folder, os.W_OK):
        raise CommandError(f"cannot write {path}: no such folder or not writable", Exit.BAD_INPUT)


def write_document(path: str, document: dict[str, Any]) -> None:
    """``document`` to stdout, or to ``path`` in one step (never a file half written)."""
    text = document_text(document, path)
    if path == "-":
        sys.stdout.write(text)
        return
    target = Path(path)
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        temporary.write_text(text, encoding="utf-8")
        os.replace(temporary, target)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}", Exit.BAD_INPUT) from None
