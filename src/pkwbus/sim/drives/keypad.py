"""Values set at random at the drives' keypads (LCP), for the demo: a value that changes
with no bus write, as a person at the drive would change it.

On average once per ``every`` seconds of a line (a Poisson process, as the drive model's
trips: :mod:`pkwbus.sim.drives.model`), one drive's setting is nudged a little up or down
within its limits: a parameter the bus may write that is neither a live value nor a text,
and not one that cannot change while the motor runs (``stopped_only``) while it runs. The
nudge is 5-20 % of the value, at least one step of its resolution, and goes back towards
the factory setting two times in three, so that the values wander around it.

Pure: the caller passes the time and the random generator, so tests drive it with a fake
clock and a fixed seed. The change itself is :meth:`SimDrive.keypad
<pkwbus.sim.drives.drive.SimDrive.keypad>`, which logs it.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw import Width
from pkwbus.protocol.values import ValueType, decode_value, encode_value
from pkwbus.sim.drives.descriptions import factory_raw
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.table import ParamSpec

__all__ = ["RandomKeypad", "nudged", "settable"]


def settable(spec: ParamSpec) -> bool:
    """Whether a person at the keypad may set ``spec`` here: a number the bus may write,
    not a live value."""
    return spec.writable and spec.live is None and spec.vtype is not ValueType.TEXT


def nudged(spec: ParamSpec, raw: int, factory: int, rng: random.Random) -> int | None:
    """Another raw value near ``raw`` within the limits of ``spec`` (and of its type);
    None when neither a step up nor one down stays within them."""
    number, home = _number(spec, raw), _number(spec, factory)
    resolution = 0.0 if spec.vtype is ValueType.F32 else float(spec.scaling.factor)
    step = max(abs(number) * rng.uniform(0.05, 0.2), resolution)
    if step == 0:  # a float at 0: a twentieth of its span, or 1
        low, high = spec.minimum, spec.maximum
        step = (high - low) / 20 if low is not None and high is not None and high > low else 1.0
    towards = 0.5 if home == number else (2 / 3 if home > number else 1 / 3)
    directions = (1, -1) if rng.random() < towards else (-1, 1)
    for direction in directions:
        found = _raw_within(spec, number + direction * step)
        if found is not None and found != raw:
            return found
    return None


class RandomKeypad:
    """Random keypad changes on one line: on average one per ``every`` seconds.

    ValueError for an ``every`` that is not a finite number of seconds above 0.
    """

    def __init__(self, every: float, rng: random.Random, now: float) -> None:
        if not (math.isfinite(every) and every > 0):
            raise ValueError(f"keypad changes every {every!r} s: give a time above 0")
        self.every = every
        self.rng = rng
        self._last = now

    def due(self, now: float) -> bool:
        """Whether a change comes between the last call and ``now`` (one draw; none when
        time has not moved on)."""
        dt = now - self._last
        if dt <= 0:
            return False
        self._last = now
        return self.rng.random() < -math.expm1(-dt / self.every)

    def change(self, now: float, drives: Sequence[SimDrive]) -> SimDrive | None:
        """One of ``drives`` gets a setting nudged at its keypad at ``now``; that drive, or
        None when the one drawn has nothing it may change now."""
        if not drives:
            return None
        drive = self.rng.choice(drives)
        drive.tick(now)  # whether the motor runs now
        params = drive.params
        specs = [
            s
            for s in params.specs.values()
            if settable(s) and not (s.stopped_only and drive.running)
        ]
        if not specs:
            return None
        spec = self.rng.choice(specs)
        index = self.rng.randrange(spec.elements)
        raw = params.raw.get((spec.pnu, index))
        factory = factory_raw(spec, index) if raw is not None else None
        if raw is None or not isinstance(factory, int):
            return None
        new = nudged(spec, raw, factory, self.rng)
        if new is None:
            return None
        try:
            drive.keypad(spec.pnu, new, index)
        except ValueError:
            return None
        return drive


def _number(spec: ParamSpec, raw: int) -> float:
    return float(decode_value(raw, spec.vtype.width or Width.DWORD, spec.vtype, spec.scaling))


def _raw_within(spec: ParamSpec, number: float) -> int | None:
    """The raw number nearest ``number`` (a float to two decimals), None when it is
    outside the type or the limits."""
    if spec.vtype is ValueType.F32:
        number = round(number, 2)
    try:
        raw = encode_value(number, spec.vtype, spec.scaling)
    except LocalProtocolError:
        return None
    value = _number(spec, raw)
    too_low = spec.minimum is not None and value < spec.minimum
    too_high = spec.maximum is not None and value > spec.maximum
    return None if too_low or too_high else raw
