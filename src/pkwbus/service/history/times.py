"""Times as pkwbus writes them for people and programs: ISO 8601 in UTC, to the
millisecond (the API's events and settings, a backup document's time)."""

from __future__ import annotations

import datetime

__all__ = ["iso_time"]


def iso_time(seconds: float) -> str:
    """Wall-clock seconds as ISO 8601 in UTC, to the millisecond."""
    moment = datetime.datetime.fromtimestamp(seconds, datetime.UTC)
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")
