"""A value as it was read: what a job answered and what the read model keeps of each
polled parameter. Knows no bus, so the planner's jobs and the snapshot both can say it."""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.catalog.description import Value

__all__ = ["Reading"]


@dataclass(frozen=True, slots=True)
class Reading:
    """A value decoded, its raw number (None: a text), and when it was read."""

    value: Value
    raw: int | None
    timestamp: float  # wall clock, seconds
