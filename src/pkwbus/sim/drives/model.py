"""The physics of a simulated drive: ramp, current, power, energy, alarms, status word,
and what it remembers of its trips (:mod:`pkwbus.sim.drives.logs`).

Pure: the caller passes the time (``update(now, ...)``) and the random
generator, so tests drive it with a fake clock and a fixed seed.

Times the drive counts itself, in whole milliseconds of the model's time: ``runtime_ms``
since the last power-up (SINAMICS r2114, which starts when the Control Unit is powered
and stops when it is switched off: SINAMICS CU240D-2 Operating Instructions 04/2018,
section 8.2), and ``powered_ms`` over all power-ups (the operating time the Danfoss
alarm log's 15-32 is counted in here, in seconds; its real unit and reference are not
confirmed by a vendor document; and MICROMASTER 4's run time counter r2114, in seconds,
"the total time the drive has been powered up", kept over a power cycle: MICROMASTER 440
Parameter List 01/06, r2114). Neither counts while the drive is off
(:meth:`DriveModel.power_cycle` with ``off``).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from pkwbus.protocol import pzd
from pkwbus.protocol.pzd import Profile
from pkwbus.sim.drives.logs import (
    ALARM_FIELDS,
    BUFFERED_ALARM_FIELDS,
    FAULT_FIELDS,
    AlarmBuffer,
    AlarmLog,
    FaultBuffer,
    runtime_words,
)
from pkwbus.sim.drives.mm4 import FIELDS as MM4_FIELDS
from pkwbus.sim.drives.mm4 import Mm4FaultBuffer, counter_words
from pkwbus.sim.drives.profidrive_buffer import ProfidriveFaultBuffer

__all__ = [
    "ALARMS",
    "SQRT3",
    "TRIPS_PER_HOUR",
    "WARNINGS_PER_HOUR",
    "WARNING_BITS",
    "DriveModel",
    "Limits",
    "ModelConfig",
]

SQRT3 = math.sqrt(3.0)
WARNINGS_PER_HOUR = 12.0  # the defaults of `pkwbus simulate --warnings-per-hour`
TRIPS_PER_HOUR = 1.0  # and of --trips-per-hour
PAST_TRIP_HOURS = 6  # hours between two trips of a drive's past (ModelConfig.past_trips)


@dataclass(frozen=True, slots=True)
class ModelConfig:
    """The motor and how often things go wrong (rates per second; 0 = never)."""

    rated_power_kw: float = 11.0
    rated_current_a: float = 21.0
    dc_link_v: float = 560.0
    noise: float = 0.01  # relative noise of current and power
    warning_rate: float = WARNINGS_PER_HOUR / 3600
    warning_seconds: float = 20.0
    trip_rate: float = TRIPS_PER_HOUR / 3600
    trip_reset_seconds: float = 30.0  # a local operator resets the trip; 0 = never
    # Trips already in the drive's own logs when it is made, from before it was simulated:
    # each acknowledged a minute after it came, PAST_TRIP_HOURS apart (the first an hour
    # into the drive's runtime, the last PAST_TRIP_HOURS before it is made).
    past_trips: int = 0


# (code shown in the alarm log, bit in the alarm word). FC: the bits of over current (6) and
# earth fault (2) as the Danfoss MCA 121 manual's table of 16-90 places them (see
# catalog/data/alarms/danfoss-fc.yaml), and one bit no table read here explains (14); the
# log codes are illustrative. PROFIdrive: illustrative.
ALARMS = {Profile.FC: ((13, 6), (14, 2), (4, 14)), Profile.PROFIDRIVE: ((1, 0), (2, 1), (11, 2))}
WARNING_BITS = (1, 9, 13)
# The SINAMICS alarm each warning bit enters in the alarm buffer (r2122): numbers and names
# from the CU240B-2/CU240E-2 List Manual (catalog/data/alarms/siemens-g120.yaml); which
# alarm goes with which bit is illustrative.
BUFFERED_ALARMS = {1: 7409, 9: 30030, 13: 7402}


@dataclass(slots=True)
class Limits:
    """What the parameters say about the motion: maximum frequency and ramp times."""

    max_frequency: float = 50.0
    ramp_up: float = 5.0
    ramp_down: float = 5.0


@dataclass
class DriveModel:
    profile: Profile
    rng: random.Random
    config: ModelConfig = field(default_factory=ModelConfig)
    log_length: int = 10
    now: float = 0.0
    running: bool = True
    setpoint: float = 40.0  # Hz
    frequency: float = 40.0
    energy: float = 0.0  # kWh
    hours: float = 0.0
    alarm_word: int = 0
    warning_word: int = 0
    tripped: bool = False
    bus_control: bool = False
    control_word: int = 0
    received: list[int] = field(default_factory=list)
    runtime_ms: int = 0  # since the last power-up (r2114)
    powered_ms: int = 0  # over all power-ups
    power_ups: int = 1  # Danfoss 15-03; the simulated drive's first is its creation
    faults: FaultBuffer = field(default_factory=FaultBuffer)  # SINAMICS r0947 and the rest
    alarms: AlarmBuffer = field(default_factory=AlarmBuffer)  # SINAMICS r2122 and the rest
    mm4: Mm4FaultBuffer = field(default_factory=Mm4FaultBuffer)  # MICROMASTER 4 r0947, r0948
    profidrive: ProfidriveFaultBuffer | None = None  # a DP slave's PROFIdrive P947, P948
    off_until: float = 0.0  # switched off until then (the model's time): nothing counts
    log: AlarmLog = field(init=False)  # Danfoss 15-30..15-32, ``log_length`` entries
    _limits: Limits = field(default_factory=Limits)  # as at the last update
    _tripped_at: float = 0.0
    _warning_until: float = 0.0

    def __post_init__(self) -> None:
        self.log = AlarmLog(self.log_length)
        self._past(self.config.past_trips)

    def _past(self, trips: int) -> None:
        """``trips`` trips in the logs, from before now (the drive has run for a while)."""
        if trips <= 0:
            return
        hour = 3_600_000
        self.runtime_ms = self.powered_ms = (trips * PAST_TRIP_HOURS + 1) * hour
        for k in range(trips):
            at = (k * PAST_TRIP_HOURS + 1) * hour
            code, _ = self.rng.choice(ALARMS[self.profile])
            value = self.rng.randrange(1500, 3000)  # an output current in 0.01 A
            self.faults.enter(code, value, at)
            self.faults.acknowledge(at + 60_000)
            self.mm4.enter(code, value, at // 1000)
            self.mm4.acknowledge()
            alarm = BUFFERED_ALARMS[self.rng.choice(WARNING_BITS)]  # a warning before it
            self.alarms.come(alarm, value, at - 20_000)
            self.alarms.go(alarm, at - 5_000)
            self.log.enter(code, value, at // 1000)

    @property
    def alarm_log(self) -> list[int]:
        """The codes of the Danfoss alarm log, newest first."""
        return [alarm.code for alarm in self.log.entries]

    # -------------------------------------------------------------- time

    def update(self, now: float, limits: Limits) -> None:
        """Advance the model to ``now``."""
        dt = now - self.now
        if dt <= 0:
            return
        elapsed = _ms(now) - _ms(max(self.now, min(self.off_until, now)))  # powered
        self.runtime_ms += elapsed
        self.powered_ms += elapsed
        self._limits = limits
        before = self._load_kw(limits)
        self._ramp(dt, limits)
        self.energy += (before + self._load_kw(limits)) / 2 * dt / 3600
        if self.frequency > 0:
            self.hours += dt / 3600
        self.now = now
        self._events(dt)

    def _ramp(self, dt: float, limits: Limits) -> None:
        target = min(self.setpoint, limits.max_frequency) if self.running else 0.0
        if self.tripped:
            target = 0.0
        if self.frequency < target:
            rate = limits.max_frequency / max(limits.ramp_up, 1e-3)
            self.frequency = min(target, self.frequency + rate * dt)
        else:
            rate = limits.max_frequency / max(limits.ramp_down, 1e-3)
            self.frequency = max(target, self.frequency - rate * dt)

    def _events(self, dt: float) -> None:
        cfg = self.config
        if self.tripped:
            if cfg.trip_reset_seconds and self.now - self._tripped_at >= cfg.trip_reset_seconds:
                self.reset()
        elif self._chance(cfg.trip_rate, dt):
            code, bit = self.rng.choice(ALARMS[self.profile])
            self.trip(code, bit)
        if self.warning_word and self.now >= self._warning_until:
            self.warn(None)
        if not self.warning_word and self._chance(cfg.warning_rate, dt):
            self.warn(self.rng.choice(WARNING_BITS))
            self._warning_until = self.now + cfg.warning_seconds

    def _chance(self, rate: float, dt: float) -> bool:
        return rate > 0 and self.rng.random() < -math.expm1(-rate * dt)

    # ------------------------------------------------------------ events

    def trip(self, code: int, bit: int | None = None, value: int | None = None) -> None:
        """Trip with fault (alarm) ``code`` now: the motor coasts; both logs get the code,
        ``value`` (default: the output current at the trip in 0.01 A, an illustrative
        choice) and the time. ``bit``: of the alarm word (default: the code's in
        :data:`ALARMS`, else 0)."""
        if bit is None:
            bit = dict(ALARMS[self.profile]).get(code, 0)
        if value is None:
            value = round(self._current(self._limits) * 100)
        self.faults.enter(code, value, self.runtime_ms)
        self.log.enter(code, value, self.powered_ms // 1000)
        self.mm4.enter(code, value, self.powered_ms // 1000)
        if self.profidrive is not None:
            self.profidrive.enter(code, value, self.runtime_ms, self.powered_ms)
        self.tripped = True
        self._tripped_at = self.now
        self.alarm_word |= 1 << bit
        self.frequency = 0.0

    def warn(self, bit: int | None) -> None:
        """A warning comes (``bit`` of the warning word), or the one there goes (None); the
        SINAMICS alarm buffer enters it or moves it into its history. Its value: the output
        current in 0.01 A (illustrative)."""
        for was, code in BUFFERED_ALARMS.items():
            if self.warning_word >> was & 1:
                self.alarms.go(code, self.runtime_ms)
        self.warning_word = 0 if bit is None else 1 << bit
        if bit is not None and bit in BUFFERED_ALARMS:
            value = round(self._current(self._limits) * 100)
            self.alarms.come(BUFFERED_ALARMS[bit], value, self.runtime_ms)

    def reset(self) -> None:
        """The trip is acknowledged. The SINAMICS fault buffer moves the active fault case
        to the acknowledged ones (r0947[0..7] are then 0); Danfoss's alarm log (15-30)
        keeps its entries."""
        self.tripped = False
        self.alarm_word = 0
        self.faults.acknowledge(self.runtime_ms)
        self.mm4.acknowledge()
        if self.profidrive is not None:
            self.profidrive.acknowledge()

    def power_cycle(self, off: float = 0.0) -> None:
        """The drive is switched off now and on again ``off`` seconds later (of the
        model's time, which keeps going; 0: at once): neither runtime counts those
        seconds, the SINAMICS runtime starts again from 0, MICROMASTER 4's run time
        counter goes on from where it stood, one more power-up is counted, the motor has
        coasted to a stop. The logs are kept, and a trip still waits for its
        acknowledgement: whether a real drive keeps its buffer over a power cycle is not
        confirmed by the documents read."""
        self.runtime_ms = 0
        self.power_ups += 1
        self.frequency = 0.0
        self.off_until = self.now + off

    def apply_control(self, ctw: int, ref: int | None, limits: Limits) -> None:
        """Process data from the master; acted on only with CTW bit 10 set."""
        self.control_word = ctw
        self.bus_control = pzd.takes_control(ctw)
        if not self.bus_control:
            return
        if ctw >> 7 & 1 and self.tripped:
            self.reset()
        if self.profile is Profile.FC:
            self.running = ctw & 0x5C == 0x5C  # no DC brake, no coast, no quick stop, start
        else:
            self.running = ctw & 0x0F == 0x0F  # on, no coast, no quick stop, enable
        if ref is not None:
            self.setpoint = max(0.0, pzd.ref_to_percent(ref) * limits.max_frequency / 100)

    # ------------------------------------------------------------ readings

    def _load_kw(self, limits: Limits) -> float:
        share = self.frequency / limits.max_frequency if limits.max_frequency > 0 else 0.0
        return self.config.rated_power_kw * share**3

    def _noisy(self, value: float) -> float:
        if value == 0 or not self.config.noise:
            return value
        return value * (1 + self.rng.gauss(0.0, self.config.noise))

    def quantity(self, name: str, limits: Limits, index: int = 0) -> float:
        """A live reading by name (the ``live`` column of the parameter tables)."""
        share = self.frequency / limits.max_frequency if limits.max_frequency > 0 else 0.0
        cfg = self.config
        if name == "frequency":
            return self.frequency
        if name == "current":
            return self._noisy(self._current(limits))
        if name == "power":
            return self._noisy(self._load_kw(limits))
        if name == "output_voltage":
            return cfg.dc_link_v / SQRT3 * 1.2 * min(share, 1.0)
        if name == "dc_link":
            return cfg.dc_link_v + self.rng.uniform(-2.0, 2.0)
        if name == "energy":  # USS r0039[2], energy fed back: never by the model
            return 0.0 if index == 2 else math.floor(self.energy * 100) / 100
        if name == "hours":  # while running
            return math.floor(self.hours)
        if name == "operating_hours":  # while powered
            return self.powered_ms // 3_600_000
        if name in FAULT_FIELDS:
            return self.faults.read(name, index)
        if name in ALARM_FIELDS:
            return self.log.read(name, index)
        if name == "fault_changes":
            return self.faults.changes
        if name in BUFFERED_ALARM_FIELDS:
            return self.alarms.read(name, index)
        if name == "alarm_changes":
            return self.alarms.changes
        if name == "runtime":
            return runtime_words(self.runtime_ms)[index]
        if name in MM4_FIELDS:
            return self.mm4.read(name, index)
        if name == "mm4_runtime":
            return counter_words(self.powered_ms // 1000)[index]
        if name == "power_ups":
            return self.power_ups
        if name == "received_pzd":
            return self.received[index] if index < len(self.received) else 0
        return float(self._words(limits)[name])

    def _current(self, limits: Limits) -> float:
        """The output current in A, without noise."""
        if self.frequency <= 0:
            return 0.0
        share = self.frequency / limits.max_frequency if limits.max_frequency > 0 else 0.0
        return self.config.rated_current_a * (0.3 + 0.7 * share**2)

    def _words(self, limits: Limits) -> dict[str, int]:
        return {
            "status_word": self.status_word(limits),
            "control_word": self.control_word,
            "alarm_word": self.alarm_word,
            "warning_word": self.warning_word,
        }

    def at_reference(self, limits: Limits) -> bool:
        target = min(self.setpoint, limits.max_frequency)
        return self.running and not self.tripped and abs(self.frequency - target) < 0.05

    def status_word(self, limits: Limits) -> int:
        at_ref = self.at_reference(limits)
        warning = bool(self.warning_word)
        if self.profile is Profile.FC:
            return pzd.status_word(
                Profile.FC,
                control_ready=True,
                drive_ready=not self.tripped,
                enabled=not self.tripped,
                trip=self.tripped,
                warning=warning,
                at_reference=at_ref,
                bus_control=self.bus_control,
                frequency_within_limit=True,
                running=self.frequency > 0,
            )
        return pzd.status_word(
            Profile.PROFIDRIVE,
            ready_to_switch_on=not self.tripped,
            ready=not self.tripped,
            operation_enabled=self.running and not self.tripped,
            fault=self.tripped,
            no_coast_stop=True,
            no_quick_stop=True,
            switching_on_inhibited=self.tripped,
            warning=warning,
            speed_within_tolerance=at_ref,
            control_requested=True,
            reference_reached=at_ref,
        )

    def mav(self, limits: Limits) -> int:
        """Main actual value: output frequency, 0x4000 = 100 % of the maximum frequency."""
        if limits.max_frequency <= 0:
            return 0
        percent = max(-199.0, min(199.0, self.frequency / limits.max_frequency * 100))
        return pzd.percent_to_ref(percent)


def _ms(seconds: float) -> int:
    """A time of the model in whole milliseconds: differences of these add up exactly."""
    return round(seconds * 1000)
