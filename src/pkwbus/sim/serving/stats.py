"""Counters of what the simulator saw, answered and injected; readable while it runs."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import Any

from pkwbus.sim.config import FAULT_KINDS

__all__ = ["DRIVE_COUNTERS", "INJECTED_KINDS", "LINE_COUNTERS", "SimStats"]

INJECTED_KINDS = (*FAULT_KINDS, "dead")
LINE_COUNTERS = (
    "requests",
    "responses",
    "broadcasts",
    "control_taken",
    "lagged",
    "bad_requests",
    "malformed",
    "ignored",
    "unsent",
)
DRIVE_COUNTERS = ("requests", "responses", "control_taken", "lagged", "malformed")


class SimStats:
    """Line totals, injected faults by kind, and the same per drive.

    ``requests``: telegrams received with a valid frame; ``bad_requests``:
    framing errors on the way in; ``ignored``: telegrams for addresses no
    simulated drive has; ``lagged``: answers sent meanwhile under PKW lag
    (AK 0 or stale; part of the timing, not a fault); ``malformed``: valid
    frames a drive could not read (wrong length for its PKW/PZD shape).
    """

    def __init__(self, addresses: Iterable[int]) -> None:
        self.line: Counter[str] = Counter()
        self.injected: Counter[str] = Counter()
        self.drives: dict[int, Counter[str]] = {a: Counter() for a in addresses}
        self.drive_injected: dict[int, Counter[str]] = {a: Counter() for a in self.drives}

    def count(self, key: str, address: int | None = None, n: int = 1) -> None:
        """Count on the line, and for ``address`` when given."""
        self.line[key] += n
        if address is not None:
            self.drives[address][key] += n

    def count_drive(self, address: int, key: str, n: int = 1) -> None:
        self.drives[address][key] += n

    def inject(self, kind: str, address: int) -> None:
        self.injected[kind] += 1
        self.drive_injected[address][kind] += 1

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {key: self.line[key] for key in LINE_COUNTERS}
        out["injected"] = {kind: self.injected[kind] for kind in INJECTED_KINDS}
        out["per_drive"] = {
            str(address): {
                **{key: counter[key] for key in DRIVE_COUNTERS},
                "injected": {k: self.drive_injected[address][k] for k in INJECTED_KINDS},
            }
            for address, counter in self.drives.items()
        }
        return out
