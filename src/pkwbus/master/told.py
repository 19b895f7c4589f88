"""What the snapshot's writer tells people of a line's events: one log line per thing that
changed, in the runner's logger (a description settled or left unanswered, a drive's PKW
length learned or in conflict)."""

from __future__ import annotations

import logging
from collections.abc import Callable

from pkwbus.catalog.alarms import Alarm
from pkwbus.catalog.precedence import Disagreement, disagreements
from pkwbus.master.planning.describing import ASK_AGAIN
from pkwbus.master.planning.outcomes import Answered, Outcome, Rejected
from pkwbus.master.planning.plan import (
    DescriptionSettled,
    HealthChanged,
    LeftUnanswered,
    PkwLengthTold,
    PollSpec,
)
from pkwbus.protocol.pkw.length import AUTO, shown

__all__ = [
    "REFUSAL_RETELL",
    "Refusals",
    "alarm_came",
    "alarm_went",
    "described",
    "health",
    "pkw_length",
    "port",
    "unanswered",
]

log = logging.getLogger("pkwbus.master.runner")  # what the runner records

REFUSAL_RETELL = 24 * 3600.0  # seconds between log lines of a poll the drive keeps refusing


class Refusals:
    """A poll the drive refuses is logged once with the fault text, then once a day while
    the refusals last; its first answer after them is logged too."""

    def __init__(self, line: str, clock: Callable[[], float]) -> None:
        self.line = line
        self._clock = clock
        # A poll the drive refuses, by (drive, parameter, index): when it was last told.
        self._refused: dict[tuple[str, str, int], float] = {}

    def forget(self, drive: str) -> None:
        self._refused = {k: v for k, v in self._refused.items() if k[0] != drive}

    def tell(self, drive: str, poll: PollSpec, outcome: Outcome) -> None:
        if not self._refused and not isinstance(outcome, Rejected):
            return  # the usual answer: no poll was refused, nothing to tell
        key, ctx = (drive, poll.parameter, poll.index), {"line": self.line, "drive": drive}
        where = poll.parameter + (f"[{poll.index}]" if poll.index else "")
        if isinstance(outcome, Rejected):
            now = self._clock()
            told = self._refused.get(key)
            if told is None or now - told >= REFUSAL_RETELL:
                again = "" if told is None else " (still, every poll)"
                log.warning(
                    "drive %s refuses the poll of %s%s: %s",
                    drive, where, again, outcome.text or outcome.short, extra=ctx,
                )  # fmt: skip
                self._refused[key] = now
        elif isinstance(outcome, Answered) and self._refused.pop(key, None) is not None:
            log.info("drive %s answers the poll of %s again", drive, where, extra=ctx)


def unanswered(line: str, event: LeftUnanswered) -> None:
    """The drive left its descriptions unanswered: one line for all its parameters."""
    log.warning("drive %s: %s: the catalog's descriptions are used for the parameters still"
                " waiting, and it is asked again in %d minutes", event.drive, event.why,
                ASK_AGAIN // 60, extra={"line": line, "drive": event.drive})  # fmt: skip


def described(line: str, event: DescriptionSettled) -> tuple[Disagreement, ...]:
    """A settled description's log lines: the catalog's used where the drive gave none, a
    parameter not polled for want of a type, a writable parameter the drive says is
    read-only, and each field the drive contradicts the catalog on (returned)."""
    drive, target, found = event.drive, event.target, event.description
    ctx = {"line": line, "drive": drive}
    left = isinstance(event, LeftUnanswered)
    if found is None and not left and event.first and not event.withheld:
        log.info("drive %s: %s: %s; the catalog's description is used", drive,
                 target.parameter, event.why, extra=ctx)  # fmt: skip
    if event.withheld and event.first:
        log.info(
            "drive %s: %s is not polled: no vendor document types it, and the drive did"
            " not describe its type (%s)", drive, target.parameter,
            event.why or "no type in its description", extra=ctx,
        )  # fmt: skip
    if found is not None and found.read_only and target.writable and event.first:
        log.warning(
            "drive %s describes %s as read-only, but the configuration lists it as"
            " writable: the drive will refuse its writes", drive, target.parameter,
            extra=ctx,
        )  # fmt: skip
    if found is None or target.catalog is None:
        return ()
    contradicts = tuple(disagreements(found, target.catalog))
    for d in contradicts:
        log.warning(
            "drive %s: %s: the drive gives its %s as %s, the catalog as %s; the"
            " drive's is used", drive, target.parameter, d.field, d.drive, d.catalog,
            extra=ctx,
        )  # fmt: skip
    return contradicts


def health(line: str, event: HealthChanged) -> None:
    """A drive shown up again (and why), or down (and why)."""
    ctx = {"line": line, "drive": event.drive}
    if event.reason and event.up:
        log.info("drive %s %s", event.drive, event.reason, extra=ctx)
    elif event.reason:
        log.warning("drive %s is down: %s (probing at back-off)", event.drive, event.reason,
                    extra=ctx)  # fmt: skip


def port(line: str, level: int, text: str, repeated: bool) -> None:
    """A line's port opened, failed or was refused, at ``level``: once per outage (at
    debug level only where it is ``repeated``: the same outage told already)."""
    log.log(logging.DEBUG if repeated else level, "line %s: %s", line, text, extra={"line": line})


def pkw_length(line: str, event: PkwLengthTold) -> None:
    """One log line per change of what a drive's PKW length is known to be."""
    length, drive = event.length, event.drive
    ctx = {"line": line, "drive": drive}
    conflict = length.conflict
    if not isinstance(conflict, str):
        log.warning(
            "drive %s answers with a PKW length of %s, but pkw_words is %s: no write goes"
            " out to it until they agree (set pkw_words: %s, or auto)",
            drive, shown(conflict), shown(length.configured),
            "127" if conflict is None else conflict, extra=ctx,
        )  # fmt: skip
    elif length.configured != AUTO:
        log.info("drive %s answers with its configured PKW length again", drive, extra=ctx)
    elif length.known:
        log.info("drive %s: PKW length %s, learned from its answers", drive,
                 shown(length.words), extra=ctx)  # fmt: skip


def alarm_came(line: str, drive: str, alarm: Alarm) -> None:
    """An alarm or warning the drive shows now (the parameter that showed it)."""
    log.warning("drive %s: %s %s (%s)", drive, alarm.kind, alarm.shown, alarm.parameter,
                extra={"line": line, "drive": drive})  # fmt: skip


def alarm_went(line: str, drive: str, alarm: Alarm) -> None:
    log.info("drive %s: %s %s is gone", drive, alarm.kind, alarm.shown,
             extra={"line": line, "drive": drive})  # fmt: skip
