"""The serial adapters of this machine, with the names that survive a replug.

pyserial lists the ports (``/dev/ttyUSB0``, ``/dev/ttyACM0``, native UARTs);
udev's ``/dev/serial/by-id`` links give each USB adapter a name built from
its vendor, product and serial number, which stays the same when the adapter
is plugged into another socket or the kernel numbers it differently. FTDI
adapters hold received bytes for their latency timer (16 ms by default)
before passing them on; the kernel shows it in sysfs.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

__all__ = [
    "DEV",
    "Adapter",
    "PortInfo",
    "by_id_names",
    "describe",
    "list_adapters",
    "unstable_name",
]

DEV = Path("/dev")
SYS = Path("/sys")


class PortInfo(Protocol):
    """What pyserial's ``ListPortInfo`` tells of a port."""

    device: str
    name: str
    description: str
    vid: int | None
    pid: int | None
    serial_number: str | None
    manufacturer: str | None
    product: str | None


@dataclass(frozen=True)
class Adapter:
    device: str
    by_id: tuple[str, ...] = field(default_factory=tuple)
    by_path: tuple[str, ...] = field(default_factory=tuple)
    description: str = ""
    vid: int | None = None
    pid: int | None = None
    serial_number: str | None = None
    manufacturer: str | None = None
    product: str | None = None
    driver: str | None = None
    latency_timer_ms: int | None = None

    @property
    def stable_name(self) -> str:
        """The name to put in a configuration: by-id when udev made one."""
        return self.by_id[0] if self.by_id else self.device

    @property
    def usb_id(self) -> str:
        return (
            f"{self.vid:04x}:{self.pid:04x}"
            if self.vid is not None and self.pid is not None
            else ""
        )

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["by_id"] = list(self.by_id)
        out["by_path"] = list(self.by_path)
        out["stable_name"] = self.stable_name
        return out


def list_adapters() -> list[Adapter]:
    """Every serial port pyserial finds, described; empty when there is none."""
    from serial.tools import list_ports

    return describe(list_ports.comports())


def describe(ports: Iterable[PortInfo], *, dev: Path = DEV, sysfs: Path = SYS) -> list[Adapter]:
    """``ports`` with their udev links, kernel driver and latency timer."""
    by_id = _links(dev / "serial" / "by-id")
    by_path = _links(dev / "serial" / "by-path")
    adapters = []
    for port in ports:
        real = os.path.realpath(port.device)
        tty = sysfs / "class" / "tty" / port.name / "device"
        adapters.append(
            Adapter(
                device=port.device,
                by_id=tuple(sorted(by_id.get(real, ()))),
                by_path=tuple(sorted(by_path.get(real, ()))),
                description=port.description if port.description != "n/a" else "",
                vid=port.vid,
                pid=port.pid,
                serial_number=port.serial_number,
                manufacturer=port.manufacturer,
                product=port.product,
                driver=_driver(tty),
                latency_timer_ms=_int_file(tty / "latency_timer"),
            )
        )
    return sorted(adapters, key=lambda a: a.device)


def unstable_name(device: str) -> bool:
    """Whether ``device`` is a kernel-numbered USB tty that may change on replug."""
    name = os.path.basename(device)
    return device.startswith("/dev/") and name.startswith(("ttyUSB", "ttyACM"))


def by_id_names(device: str, *, dev: Path = DEV) -> list[str]:
    """The ``/dev/serial/by-id`` links to ``device`` on this machine, sorted; empty if none."""
    return sorted(_links(dev / "serial" / "by-id").get(os.path.realpath(device), []))


def _links(folder: Path) -> dict[str, list[str]]:
    """Target -> the links in ``folder`` that point to it."""
    out: dict[str, list[str]] = {}
    try:
        entries = list(folder.iterdir())
    except OSError:
        return out
    for link in entries:
        if link.is_symlink():
            out.setdefault(os.path.realpath(link), []).append(str(link))
    return out


def _driver(device: Path) -> str | None:
    try:
        return os.path.basename(os.readlink(device / "driver"))
    except OSError:
        return None


def _int_file(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None
