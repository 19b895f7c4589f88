"""The lines of a soak: what each simulates, what the service polls and may write.

Line ``i`` speaks FC, USS and PROFIBUS DP in turn, on TCP and on a pty in turn,
so three lines already have each protocol and both kinds of port. Every line
runs at 19200 baud with the simulator spending the wire time of each telegram.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["BAUDRATE", "DriveSpec", "LineSpec", "service_config", "soak_lines", "write_value"]

BAUDRATE = 19200
PROTOCOLS = ("fc", "uss", "profibus")
FC_POLLS = ("16-13", "16-14", "16-10", "16-30", "16-90")
USS_POLLS = ("r0021", "r0024", "r0027", "r0032")


@dataclass(frozen=True)
class DriveSpec:
    name: str
    address: int
    catalog: str | None
    polls: tuple[str, ...]
    writable: tuple[str, ...] = ()
    dialect: str | None = None  # PROFIBUS: the slave's dialect
    ident: int | None = None  # PROFIBUS: the slave's ident number

    @property
    def f32(self) -> bool:
        """Whether its writable parameters are f32 (Siemens), else u32 with 2 decimals."""
        return self.catalog == "siemens-g120"


@dataclass(frozen=True)
class LineSpec:
    name: str
    protocol: str
    end: str  # "tcp" or "pty"
    drives: tuple[DriveSpec, ...] = field(default_factory=tuple)


def soak_lines(count: int) -> list[LineSpec]:
    return [_line(i) for i in range(count)]


def _line(i: int) -> LineSpec:
    protocol = PROTOCOLS[i % len(PROTOCOLS)]
    end = "pty" if i % 2 else "tcp"
    name = f"{'dp' if protocol == 'profibus' else protocol}{i}"
    if protocol == "fc":
        drives = tuple(
            DriveSpec(
                f"{name}_d{a}", a, "danfoss-fc",
                FC_POLLS + (("3-41",) if a == 1 else ()),
                ("3-41", "3-42") if a < 3 else (),
            )
            for a in (1, 2, 3)
        )  # fmt: skip
    elif protocol == "uss":
        drives = tuple(
            DriveSpec(
                f"{name}_d{a}", a, "siemens-g120",
                USS_POLLS + (("p1120",) if a == 1 else ()), ("p1120", "p1121"),
            )
            for a in (1, 2)
        )  # fmt: skip
    else:
        drives = (
            DriveSpec(f"{name}_fc", 8, "danfoss-fc", ("16-13", "16-14", "3-41"), ("3-41",),
                      "danfoss-pcv", 0x0402),
            DriveSpec(f"{name}_g120", 9, "siemens-g120", ("r0021", "r0027"), ("p1120",),
                      "profidrive", 0x80B5),
            DriveSpec(f"{name}_sj", 10, None, ("r0052",), (), "hitachi-sjpb", 0x0B6A),
        )  # fmt: skip
    return LineSpec(name, protocol, end, drives)


def service_config(
    lines: list[LineSpec], ports: dict[str, str], *, listen: str, audit_db: str, token_env: str
) -> dict[str, Any]:
    """The configuration of ``pkwbus run`` (as JSON, which is YAML) for the lines."""
    return {
        "listen": listen,
        "api": {"write_token_env": token_env},
        "audit_db": audit_db,
        "log_format": "text",
        "lines": [_line_config(line, ports[line.name]) for line in lines],
    }


def _line_config(line: LineSpec, port: str) -> dict[str, Any]:
    config: dict[str, Any] = {"name": line.name, "port": port, "protocol": line.protocol}
    config["baudrate"] = BAUDRATE
    if line.protocol == "profibus":
        config["master_address"] = 2
    else:
        config |= {"parity": "E", "timeout": "150ms", "retries": 2}
    config["drives"] = [_drive_config(line, drive) for drive in line.drives]
    return config


def _drive_config(line: LineSpec, drive: DriveSpec) -> dict[str, Any]:
    config: dict[str, Any] = {"name": drive.name, "address": drive.address}
    if drive.catalog is not None:
        config["catalog"] = drive.catalog
    if line.protocol == "profibus":
        config |= {"dialect": drive.dialect, "ident": drive.ident}
    config["poll"] = [{"parameter": p, "every": "1s"} for p in drive.polls]
    if drive.writable:
        config["writable"] = list(drive.writable)
    return config


def write_value(drive: DriveSpec, n: int) -> float:
    """The ``n``-th value written, different for every n of a run: a ramp time of 1 s to
    600 s that the parameter holds exactly (u32 with 2 decimals; f32 in 1/64 s)."""
    if drive.f32:
        return 1.0 + (n % 38_000) / 64
    return round(1.0 + (n % 59_000) / 100, 2)
