"""A restore carried out, whichever door it came through (``POST .../restore`` of the API,
``pkwbus restore`` on a port): the plan of :func:`~pkwbus.service.history.backup.plan_restore`
written step by step in the backup's order, each write read back.

The same rules for both doors:

- a read-back with another value, a write or read-back without an answer, or a write the
  service cancelled stops the restore (:data:`STOPPING`): the rest is reported
  ``not_sent`` with where it stopped;
- a write the drive refuses is reported with the drive's reason and the restore goes
  on; one refused for the motor running (fault 17, :data:`RUNNING_FAULT`) is marked
  ``when_stopped``: it can be written once the motor is stopped.

How one step is written (through the service's one write path, or a command's line) is
the door's: ``write`` gives the step's outcome (``ok``, ``rejected``, ``mismatch``,
``unverified``, ``timeout``, ``line_error``, ``cancelled``, ``invalid``, ``dry_run``) and
what it says of it.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Sequence
from typing import Any

from pkwbus.service.history.backup import Planned

__all__ = ["RUNNING_FAULT", "STOPPING", "Write", "carry_out"]

# Fault 17 (FC: "Certain parameters can only be changed when the motor is turned off",
# Danfoss FC protocol, PKW error codes; Siemens: "cannot be executed because of the
# operating state", SINAMICS/MICROMASTER parameter channel error numbers).
RUNNING_FAULT = 17
# What stops a restore: the drive holds another value than the one written, it did not
# answer (the write or its read-back), or the write was cancelled (the service stops).
STOPPING = frozenset({"mismatch", "unverified", "timeout", "line_error", "cancelled"})

# One planned step written and read back: its outcome and what the door says of it.
Write = Callable[[Planned], Awaitable[dict[str, Any]]]


async def carry_out(plan: Sequence[Planned], write: Write) -> list[dict[str, Any]]:
    """Each step of ``plan`` written in order; what stops a restore reports the rest
    ``not_sent``. One result a step: the step (parameter, index, from, to) and its
    outcome."""
    results: list[dict[str, Any]] = []
    stopped: str | None = None
    for step in plan:
        if stopped is not None:
            results.append({**step.as_dict(), "outcome": "not_sent", "detail": stopped})
            continue
        result = {**step.as_dict(), **await write(step)}
        if result["outcome"] == "rejected" and result.get("fault") == RUNNING_FAULT:
            result["when_stopped"] = True  # only while the motor is stopped
        results.append(result)
        if result["outcome"] in STOPPING:
            where = step.parameter + (f"[{step.index}]" if step.index else "")
            stopped = f"the restore stopped at {where}: {result['outcome']}"
    return results
