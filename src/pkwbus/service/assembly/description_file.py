"""The drives' descriptions kept between runs: a small JSON file beside the audit database.

Keyed by what identifies a drive's model and software
(:mod:`pkwbus.master.planning.identity`), so that a restart does not describe
everything again and a drive replaced by another model is described afresh.
A file that cannot be read is logged once and started afresh: descriptions
are read from the drives again, nothing is lost. A file that cannot be
written is logged once; the service goes on with what it has in memory.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from pkwbus.master.planning.identity import DescriptionBook

__all__ = ["DescriptionFile", "description_path"]

log = logging.getLogger(__name__)


def description_path(audit_db: Path) -> Path:
    """``var/audit.sqlite`` -> ``var/audit.sqlite.descriptions.json``."""
    return audit_db.with_name(audit_db.name + ".descriptions.json")


class DescriptionFile:
    """Loads the book once and stores it again whenever a drive described something new."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.book = self._load()
        self._failed = False
        self._written = ""  # the text last written: drives of one kind tell the same

    def _load(self) -> DescriptionBook:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return DescriptionBook()
        except OSError as exc:
            log.warning("cannot read %s (%s): the drives are described afresh", self.path,
                        exc.strerror or exc)  # fmt: skip
            return DescriptionBook()
        try:
            return DescriptionBook.from_json(json.loads(text))
        except (ValueError, TypeError, RecursionError) as exc:  # JSONDecodeError is a ValueError
            log.warning("%s is not a file of drive descriptions (%s): the drives are"
                        " described afresh", self.path, exc)  # fmt: skip
            return DescriptionBook()

    def save(self) -> None:
        """Write the book (a new file renamed over the old one: never half a file)."""
        text = json.dumps(self.book.to_json(), indent=1)
        if text == self._written:
            return
        temporary = self.path.with_name(self.path.name + ".new")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            temporary.write_text(text, encoding="utf-8")
            os.replace(temporary, self.path)
        except OSError as exc:
            if not self._failed:
                log.warning("cannot store the drives' descriptions in %s (%s): they are"
                            " read from the drives again at the next start", self.path,
                            exc.strerror or exc)  # fmt: skip
            self._failed = True
            return
        if self._failed:
            log.info("the drives' descriptions are stored in %s again", self.path)
        self._failed = False
        self._written = text
