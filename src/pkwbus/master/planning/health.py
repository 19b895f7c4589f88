"""Drive health: up while it answers; down after consecutive failures, then probed at back-off."""

from __future__ import annotations

from dataclasses import dataclass

from pkwbus.link.backoff import Backoff

__all__ = ["DriveHealth", "HealthPolicy"]


@dataclass(frozen=True, slots=True)
class HealthPolicy:
    down_after: int = 3  # consecutive exchanges without a valid answer
    probe_initial: float = 1.0
    probe_cap: float = 60.0
    # False where the wire tells a drive's health itself (a PROFIBUS slave's state):
    # missing answers then never take it down, nor is it probed.
    from_answers: bool = True


class DriveHealth:
    """Counts consecutive failures; says when a down drive is due for a probe."""

    __slots__ = ("_backoff", "failures", "next_probe", "policy", "up")

    def __init__(self, policy: HealthPolicy) -> None:
        self.policy = policy
        self.up = True
        self.failures = 0
        self.next_probe = 0.0
        self._backoff = Backoff(policy.probe_initial, policy.probe_cap)

    def reset(self) -> None:
        """As at the start: up until its answers say otherwise (out of maintenance)."""
        self.up = True
        self.failures = 0
        self._backoff.reset()

    def answered(self) -> bool:
        """A valid answer; True when this brings the drive back up."""
        self.failures = 0
        if self.up:
            return False
        self.up = True
        self._backoff.reset()
        return True

    def failed(self, now: float) -> bool:
        """A missing or bad answer; True when this takes the drive down."""
        if not self.policy.from_answers:
            return False
        self.failures += 1
        if not self.up:
            self.next_probe = now + self._backoff.next_delay()
            return False
        if self.failures >= self.policy.down_after:
            self.up = False
            self.next_probe = now + self._backoff.next_delay()
            return True
        return False

    def probe_due(self, now: float) -> bool:
        return not self.up and now >= self.next_probe
