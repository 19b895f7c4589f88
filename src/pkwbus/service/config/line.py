"""One RS-485 line: its port, framing and timing, and the drives on it."""

from __future__ import annotations

from typing import Annotated, Any, Literal, Self

from pydantic import (
    BeforeValidator,
    Field,
    StrictBool,
    StrictInt,
    ValidationInfo,
    field_validator,
    model_validator,
)

from pkwbus.limits import MAX_RETRIES, check_baudrate, check_port_url
from pkwbus.problems import short
from pkwbus.protocol.buses import (
    DIALECTS_BY_PROTOCOL,
    DP_MAX_ADDRESS,
    address_range,
    default_dialect,
)
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect, dialect
from pkwbus.protocol.serial import timing
from pkwbus.protocol.serial.telegram import FcAddressFormat
from pkwbus.protocol.serial.telegram import Protocol as BusProtocol
from pkwbus.protocol.values import (
    ParameterRef,
    canonical,
)
from pkwbus.service.config.base import PORT_SCHEMES, Model, Place, fail
from pkwbus.service.config.dp_problems import DpLineSettings, dp_drive_problems
from pkwbus.service.config.drive import Drive
from pkwbus.service.config.fields import (
    Alarms,
    CharTimeout,
    Delay,
    Describe,
    Name,
    Pause,
    Rs485Delay,
    SlotTime,
    Timeout,
    Watchdog,
    upper,
)
from pkwbus.sim.serving.url import SimPort, parse_sim_port

__all__ = ["MAX_DP_RETRIES", "Line", "Rs485"]

MAX_DP_RETRIES = 8  # a DP slave's request is repeated at most 8 times (DpSlave, SlaveSetup)


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


class Line(Model):
    """One RS-485 line: its port, framing and timing, and the drives on it."""

    name: Name
    port: Annotated[str, Field(strict=True)]
    protocol: BusProtocol
    baudrate: StrictInt
    parity: Annotated[Literal["E", "O", "N"], BeforeValidator(upper)] = "E"
    stopbits: Literal[1, 2] = 1
    timeout: Timeout = 0.1
    retries: StrictInt = Field(default=2, ge=0, le=MAX_RETRIES)
    pause: Pause | None = None
    inter_char_timeout: CharTimeout | None = None
    response_delay: Delay | None = None
    echo: StrictBool = False
    fc_address_format: FcAddressFormat | None = None
    low_latency: StrictBool = False  # ask the adapter's driver for 1 ms latency
    rs485: Rs485 | None = None  # kernel RS-485 mode (native UARTs)
    # PROFIBUS DP only: pkwbus's own station, the slot time, the slaves' watchdog.
    master_address: StrictInt = Field(default=2, ge=0, le=DP_MAX_ADDRESS)
    slot_time: SlotTime | None = None
    watchdog: Watchdog | None = None
    # The drives' own description elements (AK 4) over their catalogs; a drive may say otherwise.
    describe: Describe = "auto"
    alarms: Alarms = "auto"
    drives: list[Drive] = Field(min_length=1)

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

    @model_validator(mode="before")
    @classmethod
    def _drives_on_this_protocol(cls, data: Any) -> Any:
        """Each drive learns the line's protocol before it is validated (a drive that
        names one itself is told it is the line's setting)."""
        if not isinstance(data, dict) or not isinstance(data.get("drives"), list):
            return data
        given = data.get("protocol")
        if not isinstance(given, str) or given not in {p.value for p in BusProtocol}:
            return data  # the line's own error says what is wrong with it
        protocol = BusProtocol(given)
        drives = [{"protocol": protocol, **d} if isinstance(d, dict) else d for d in data["drives"]]
        return {**data, "drives": drives}

    @model_validator(mode="after")
    def _drives_fit_line(self) -> Self:
        problems = self._line_problems()
        for i, drive in enumerate(self.drives):
            problems += [
                (f"drives[{i}].{p}" if p else f"drives[{i}]", m)
                for p, m in _drive_problems(self, drive)
            ]
        problems += self._address_problems()
        if problems:
            raise fail(problems)
        return self

    def _line_problems(self) -> list[Place]:
        problems: list[Place] = []
        if self.protocol is not BusProtocol.FC and self.fc_address_format is not None:
            problems.append(("fc_address_format", "applies to protocol fc only"))
        if self.protocol is BusProtocol.PROFIBUS:
            problems += self._dp_line_problems()
        else:
            problems += [
                (key, "applies to protocol profibus only")
                for key in ("master_address", "slot_time", "watchdog")
                if key in self.model_fields_set
            ]
        sim = self.sim
        if sim is not None:
            if sim.protocol is not self.protocol:
                problems.append(
                    ("port", f"simulates protocol {sim.protocol} but the line's is {self.protocol}")
                )
            missing = sorted({d.address for d in self.drives} - set(sim.drives))
            if missing:
                listed = ",".join(str(a) for a in missing)
                problems.append(("port", f"simulates no drive at address {listed}"))
            problems += self._sim_shape_problems()
        return problems

    def _dp_line_problems(self) -> list[Place]:
        problems: list[Place] = []
        if self.parity != "E" or self.stopbits != 1:
            problems.append(("parity", "PROFIBUS characters are always 8E1: parity E, stopbits 1"))
        if self.retries > MAX_DP_RETRIES:
            problems.append(("retries", f"at most {MAX_DP_RETRIES} over PROFIBUS"))
        return problems

    def _sim_shape_problems(self) -> list[Place]:
        """One simulator answers every drive of a ``sim://`` line with one telegram shape."""
        first = self.drives[0]
        for i, drive in enumerate(self.drives[1:], start=1):
            if _sim_shape(self.protocol, drive) != _sim_shape(self.protocol, first):
                return [
                    (
                        f"drives[{i}]",
                        f"the simulated drives of a sim:// port share one dialect, IND layout "
                        f"and PKW/PZD lengths (over PROFIBUS: one PPO): {drive.name} differs"
                        f" from {first.name}",
                    )
                ]
        return []

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
        return self.fc_address_format or FcAddressFormat.RANGE_1_126

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


def _sim_shape(protocol: BusProtocol, drive: Drive) -> tuple[object, ...]:
    """The dialect, IND layout and lengths a simulator would need for ``drive``."""
    name = drive.dialect or default_dialect(protocol)
    layout = drive.ind_layout or dialect(name).default_ind_layout
    if protocol is BusProtocol.FC:
        return (name, layout)
    if protocol is BusProtocol.PROFIBUS:  # each simulated slave has its own dialect and ident
        return (drive.ppo, drive.cfg)
    return (name, layout, drive.pkw_words, drive.pzd_words)


def _drive_problems(line: Line, drive: Drive) -> list[Place]:
    problems: list[Place] = []
    low, high = line.address_range
    if not low <= drive.address <= high:
        where = f"protocol {line.protocol}"
        if line.fc_address_format is FcAddressFormat.RANGE_1_31:
            where += " with fc_address_format 1-31"
        problems.append(("address", f"{drive.address} is outside {low}-{high} for {where}"))
    allowed = DIALECTS_BY_PROTOCOL[line.protocol]
    if drive.dialect is not None and drive.dialect not in allowed:
        problems.append(
            (
                "dialect",
                f"{drive.dialect} is not for protocol {line.protocol} (use {', '.join(allowed)})",
            )
        )
        return problems
    if line.protocol is not BusProtocol.PROFIBUS:
        problems += [
            (key, "applies to protocol profibus only")
            for key in (
                "ppo",
                "ident",
                "gsd",
                "cfg",
                "user_prm",
                "dpv1",
                "parameter_access",
                "axis",
            )
            if key in drive.model_fields_set
        ]
    if line.protocol is BusProtocol.PROFIBUS:
        settings = DpLineSettings(line.master_address, line.baudrate, line.slot_time)
        problems += dp_drive_problems(settings, drive)
    elif line.protocol is BusProtocol.FC:
        for key in ("pkw_words", "pzd_words"):
            if key in drive.model_fields_set:
                problems.append(
                    (key, "applies to protocol uss only: FC telegrams have a fixed shape")
                )
    elif drive.pkw_words == 0 and (drive.poll or drive.writable):
        problems.append(("pkw_words", "is 0: the drive has no parameter channel to poll or write"))
    problems += _pnu_problems(drive, drive.pkw_dialect)
    return problems


def _pnu_problems(drive: Drive, pkw_dialect: Dialect) -> list[Place]:
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
