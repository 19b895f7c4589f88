"""The simulator's knobs: timing and fault injection."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from pkwbus.protocol.serial import timing

__all__ = ["FAULT_KINDS", "LAG_MODES", "LagMode", "SimFaults", "SimTiming"]

LagMode = Literal["none", "stale"]
LAG_MODES: tuple[LagMode, ...] = ("none", "stale")
FAULT_KINDS = ("drop", "corrupt", "truncate", "garbage", "wrong_address", "late", "stale")


@dataclass(frozen=True, slots=True)
class SimTiming:
    """How fast the simulated drives answer.

    ``response_delay``: seconds from the end of a request to the start of the
    answer. ``wire_timing`` with ``baudrate``: the ends also spend the time
    the request and the answer take on an RS-485 line (8E1: 11 bits a character).
    PKW lag: a parameter answer comes only after ``lag_telegrams`` further
    telegrams and ``lag_seconds``; meanwhile the drive answers AK 0
    (``lag_mode="none"``) or repeats its previous answer (``"stale"``).
    """

    response_delay: float = 0.003
    baudrate: int | None = None
    wire_timing: bool = False
    lag_telegrams: int = 0
    lag_seconds: float = 0.0
    lag_mode: LagMode = "none"

    def __post_init__(self) -> None:
        if self.response_delay < 0 or self.lag_seconds < 0 or self.lag_telegrams < 0:
            raise ValueError("delays and lags cannot be negative")
        if self.wire_timing and not self.baudrate:
            raise ValueError("wire timing needs a baud rate")
        if self.baudrate is not None and self.baudrate <= 0:
            raise ValueError(f"baud rate {self.baudrate} must be positive")
        if self.lag_mode not in LAG_MODES:
            raise ValueError(f"lag mode {self.lag_mode!r} is not one of {', '.join(LAG_MODES)}")

    @property
    def lagging(self) -> bool:
        return self.lag_telegrams > 0 or self.lag_seconds > 0

    def wire_seconds(self, nbytes: int) -> float:
        """Time ``nbytes`` take on the line (0 without wire timing)."""
        if not self.wire_timing or not self.baudrate:
            return 0.0
        return timing.wire_time(nbytes, timing.char_time(self.baudrate))


@dataclass(frozen=True, slots=True)
class SimFaults:
    """Probabilities (0..1) of a fault per answer, and the dead drives.

    At most one fault hits an answer: one uniform draw picks it, so the
    probabilities add up to at most 1 and each is measured as given.
    ``late`` answers arrive ``late_seconds`` after they were due.
    """

    drop: float = 0.0
    corrupt: float = 0.0
    truncate: float = 0.0
    garbage: float = 0.0
    wrong_address: float = 0.0
    late: float = 0.0
    late_seconds: float = 1.0
    stale: float = 0.0
    dead: frozenset[int] = field(default_factory=frozenset)

    def __post_init__(self) -> None:
        total = 0.0
        for kind in FAULT_KINDS:
            p = getattr(self, kind)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{kind} probability {p} is outside 0..1")
            total += p
        if total > 1.0 + 1e-9:
            raise ValueError(f"fault probabilities add up to {total:.3f}, more than 1")
        if self.late_seconds < 0:
            raise ValueError("late_seconds cannot be negative")

    def probabilities(self) -> tuple[tuple[str, float], ...]:
        return tuple((kind, float(getattr(self, kind))) for kind in FAULT_KINDS)
