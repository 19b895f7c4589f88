"""What every line has, whatever its bus: its port, framing and timing, and the drives on
it, checked against it. Each bus's line adds its own settings and checks (:mod:`.serial`,
:mod:`.profibus_line`)."""

from __future__ import annotations

import typing
from collections.abc import Mapping, Sequence
from typing import Annotated, Any, ClassVar, Generic, Literal, Self, TypeVar

from pydantic import (
    BeforeValidator,
    Field,
    ModelWrapValidatorHandler,
    StrictBool,
    StrictInt,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from pkwbus.notation.limits import MAX_RETRIES, check_baudrate, check_port_url
from pkwbus.notation.problems import short
from pkwbus.protocol.buses import DIALECTS_BY_PROTOCOL, Bus, address_range
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.serial import timing
from pkwbus.protocol.serial.telegram import FcAddressFormat
from pkwbus.protocol.values import (
    ParameterRef,
    canonical,
)
from pkwbus.service.config.base import PORT_SCHEMES, Model, Place, fail, placed
from pkwbus.service.config.drive import DriveBase
from pkwbus.service.config.fields import (
    Alarms,
    CharTimeout,
    Counters,
    Delay,
    Describe,
    Events,
    EventsEvery,
    Name,
    Pause,
    Rs485Delay,
    Settings,
    SettingsField,
    Timeout,
    upper,
)
from pkwbus.sim.serving.url import SimPort, parse_sim_port

__all__ = ["LineBase", "Rs485"]

DriveT = TypeVar("DriveT", bound=DriveBase)


def _check_port(value: str) -> str:
    if not value.strip() or any(ord(c) < 0x20 for c in value):
        raise ValueError(
            "must be a device path such as /dev/ttyUSB0 or a URL such as socket://host:port"
        )
    if "://" in value:
        scheme = value.split("://", 1)[0].lower()
        if scheme not in PORT_SCHEMES:
            known = ", ".join(f"{s}://" for s in sorted(PORT_SCHEMES))
            raise ValueError(f"unknown port URL scheme {scheme!r} (known: {known})")
        if scheme == "sim":
            parse_sim_port(value)
        check_port_url(value)
    return value


class Rs485(Model):
    """Kernel RS-485 mode of a native UART: the driver switches RTS around each transmission."""

    rts_level_for_tx: StrictBool = True
    rts_level_for_rx: StrictBool = False
    delay_before_tx: Rs485Delay = 0.0
    delay_before_rx: Rs485Delay = 0.0


class LineBase(Model, Generic[DriveT]):
    """One RS-485 line: what lines of every bus have; its drives are its bus's."""

    # Keys the line does not take, each with what a user who gives one is told.
    refused_keys: ClassVar[Mapping[str, str]] = {}

    name: Name
    port: Annotated[str, Field(strict=True)]
    protocol: Bus
    baudrate: StrictInt
    parity: Annotated[Literal["E", "O", "N"], BeforeValidator(upper)] = "E"
    stopbits: Literal[1, 2] = 1
    timeout: Timeout = 0.1
    retries: StrictInt = Field(default=2, ge=0, le=MAX_RETRIES)
    pause: Pause | None = None
    inter_char_timeout: CharTimeout | None = None
    response_delay: Delay | None = None
    echo: StrictBool = False
    low_latency: StrictBool = False  # ask the adapter's driver for 1 ms latency
    rs485: Rs485 | None = None  # kernel RS-485 mode (native UARTs)
    # The drives' own description elements (AK 4) over their catalogs; a drive may say otherwise.
    describe: Describe = "auto"
    alarms: Alarms = "auto"
    counters: Counters = "auto"
    # The drives' own fault and alarm logs, watched every ``events_every``.
    events: Events = "auto"
    events_every: EventsEvery = 10.0
    # The sweep of the drives' settings (``off``: none); a drive may say otherwise.
    settings: SettingsField = Settings()
    drives: list[DriveT] = Field(min_length=1)

    @field_validator("port")
    @classmethod
    def _port(cls, value: str) -> str:
        return _check_port(value)

    @field_validator("rs485")
    @classmethod
    def _rs485_on_a_device(cls, value: Rs485 | None, info: ValidationInfo) -> Rs485 | None:
        port = info.data.get("port")
        if value is not None and isinstance(port, str) and "://" in port:
            raise ValueError(f"applies to a serial device such as /dev/ttyS1, not {short(port)}")
        return value

    @field_validator("baudrate")
    @classmethod
    def _baudrate(cls, value: int) -> int:
        return check_baudrate(value)

    @model_validator(mode="wrap")
    @classmethod
    def _checked(cls, data: Any, handler: ModelWrapValidatorHandler[Self]) -> Self:
        """The line as its fields make it, then checked whole with its drives. The keys
        it and its drives refuse (another bus's settings) are taken out first and told
        with the fields' problems, or else with those of the whole line."""
        if not isinstance(data, dict):
            return handler(data)
        refused = [key for key in cls.refused_keys if key in data]
        data = {k: v for k, v in data.items() if k not in cls.refused_keys}
        drive_keys = cls.drive_class().refused_keys
        drives_refused: dict[int, list[str]] = {}
        if isinstance(data.get("drives"), list):
            drives: list[object] = []
            for i, drive in enumerate(data["drives"]):
                if isinstance(drive, dict) and any(key in drive for key in drive_keys):
                    drives_refused[i] = [key for key in drive_keys if key in drive]
                    drive = {k: v for k, v in drive.items() if k not in drive_keys}
                drives.append(drive)
            data["drives"] = drives
        try:
            line = handler(data)
        except ValidationError as exc:
            if not refused and not drives_refused:
                raise
            told = [(key, cls.refused_keys[key]) for key in refused]
            told += [
                (f"drives[{i}].{key}", drive_keys[key])
                for i, given in drives_refused.items()
                for key in given
            ]
            raise fail([*placed(exc.errors(include_url=False), cls), *told]) from None
        problems = line._problems(refused, drives_refused)
        if problems:
            raise fail(problems)
        return line

    @classmethod
    def drive_class(cls) -> type[DriveBase]:
        """The class of the line's drives: its bus's."""
        (found,) = typing.get_args(cls.model_fields["drives"].annotation)
        assert isinstance(found, type) and issubclass(found, DriveBase), found
        return found

    def _problems(
        self, refused: Sequence[str], drives_refused: Mapping[int, Sequence[str]]
    ) -> list[Place]:
        """What stops the line, its drives included (each refused key among them)."""
        problems = [(key, self.refused_keys[key]) for key in refused]
        problems += self._bus_problems()
        problems += self._sim_problems()
        for i, drive in enumerate(self.drives):
            told = [(key, drive.refused_keys[key]) for key in drives_refused.get(i, ())]
            problems += [
                (f"drives[{i}].{p}" if p else f"drives[{i}]", m)
                for p, m in self._drive_problems(drive, told)
            ]
        problems += self._address_problems()
        return problems

    def _bus_problems(self) -> list[Place]:
        """What stops the line on its bus (none beyond the fields' own checks here)."""
        return []

    def _bus_drive_problems(self, drive: DriveT) -> list[Place]:
        """What stops ``drive`` on this bus (none beyond the checks of every bus here)."""
        return []

    def _sim_problems(self) -> list[Place]:
        sim = self.sim
        if sim is None:
            return []
        problems: list[Place] = []
        if sim.protocol is not self.protocol:
            problems.append(
                ("port", f"simulates protocol {sim.protocol} but the line's is {self.protocol}")
            )
        missing = sorted({d.address for d in self.drives} - set(sim.drives))
        if missing:
            listed = ",".join(str(a) for a in missing)
            problems.append(("port", f"simulates no drive at address {listed}"))
        return problems + self._sim_shape_problems()

    def _sim_shape_problems(self) -> list[Place]:
        """One simulator answers every drive of a ``sim://`` line with one telegram shape."""
        first = self.drives[0]
        for i, drive in enumerate(self.drives[1:], start=1):
            if drive.sim_shape != first.sim_shape:
                return [
                    (
                        f"drives[{i}]",
                        f"the simulated drives of a sim:// port share one dialect, IND layout "
                        f"and PKW/PZD lengths (over PROFIBUS: one PPO): {drive.name} differs"
                        f" from {first.name}",
                    )
                ]
        return []

    def _drive_problems(self, drive: DriveT, told: list[Place]) -> list[Place]:
        """What stops ``drive`` on this line: its address, its dialect, the keys it refused
        (``told``), its bus's checks, the parameter numbers its dialect cannot encode."""
        problems: list[Place] = []
        low, high = self.address_range
        if not low <= drive.address <= high:
            where = f"protocol {self.protocol}"
            if self.address_format is FcAddressFormat.RANGE_1_31:
                where += " with fc_address_format 1-31"
            problems.append(("address", f"{drive.address} is outside {low}-{high} for {where}"))
        allowed = DIALECTS_BY_PROTOCOL[self.protocol]
        if drive.dialect is not None and drive.dialect not in allowed:
            problems.append(
                (
                    "dialect",
                    f"{drive.dialect} is not for protocol {self.protocol}"
                    f" (use {', '.join(allowed)})",
                )
            )
            return problems
        problems += told
        problems += self._bus_drive_problems(drive)
        problems += _pnu_problems(drive, drive.pkw_dialect)
        return problems

    def _address_problems(self) -> list[Place]:
        problems: list[Place] = []
        seen: dict[int, str] = {}
        for i, drive in enumerate(self.drives):
            first = seen.setdefault(drive.address, drive.name)
            if first != drive.name:
                problems.append(
                    (f"drives[{i}].address", f"address {drive.address} is already used by {first}")
                )
        return problems

    @property
    def address_format(self) -> FcAddressFormat:
        """How an FC line numbers its drives (FC's own setting; 1-126 on the others)."""
        return FcAddressFormat.RANGE_1_126

    @property
    def address_range(self) -> tuple[int, int]:
        return address_range(self.protocol, self.address_format)

    @property
    def sim(self) -> SimPort | None:
        """The simulated drives this line asks for, None for a real port."""
        if not self.port.lower().startswith("sim://"):
            return None
        return parse_sim_port(self.port)

    @property
    def bits_per_character(self) -> int:
        """Start bit, 8 data bits, parity bit unless N, stop bits: 11 with the default 8E1."""
        return timing.char_bits(self.parity, self.stopbits)

    @property
    def character_time(self) -> float:
        return timing.char_time(self.baudrate, self.parity, self.stopbits)

    @property
    def pause_seconds(self) -> float:
        """Pause before each request: as configured, else 3.5 character times."""
        return timing.start_pause(self.character_time, self.pause)

    @property
    def inter_char_seconds(self) -> float:
        """A gap longer than this ends a telegram: as configured, else 20 character
        times but at least 5 ms (what the line's receiver waits)."""
        return timing.inter_char_gap(self.character_time, self.inter_char_timeout)

    @property
    def response_delay_seconds(self) -> float | None:
        """The expected response delay: configured, else the simulator's, else None."""
        if self.response_delay is not None:
            return self.response_delay
        sim = self.sim
        return sim.response_delay if sim is not None else None


def _pnu_problems(drive: DriveBase, pkw_dialect: Dialect) -> list[Place]:
    """Numbers the dialect cannot encode; notation the drive does not use (r/p on a
    Danfoss drive, r0021 and p0021 both)."""
    problems: list[Place] = []
    prefixes: dict[int, ParameterRef] = {}
    for place, ref in drive.refs():
        try:
            pkw_dialect.check_pnu(ref.pnu)
        except LocalProtocolError as exc:
            problems.append((place, f"{ref}: {exc}"))
            continue
        try:
            canonical(ref, danfoss=pkw_dialect.danfoss_numbers)
        except LocalProtocolError as exc:
            problems.append((place, str(exc)))
            continue
        first = prefixes.setdefault(ref.pnu, ref) if ref.prefix else ref
        if first.prefix != ref.prefix:
            problems.append((place, f"{ref} and {first} name one parameter: write it one way"))
    return problems
