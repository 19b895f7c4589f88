"""Serial adapters: stable by-id names, USB identity, driver and FTDI latency timer."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from pkwbus.commands.ports import format_table
from pkwbus.link.adapters import describe, unstable_name


@dataclass
class FakePort:
    device: str
    name: str
    description: str = "n/a"
    vid: int | None = None
    pid: int | None = None
    serial_number: str | None = None
    manufacturer: str | None = None
    product: str | None = None


def machine(tmp: Path) -> tuple[Path, Path, list[FakePort]]:
    """A /dev and /sys with an FTDI adapter, a CDC-ACM adapter and a native UART."""
    dev, sysfs = tmp / "dev", tmp / "sys"
    (dev / "serial" / "by-id").mkdir(parents=True)
    (dev / "serial" / "by-path").mkdir(parents=True)
    for name in ("ttyUSB3", "ttyACM0", "ttyS0"):
        (dev / name).touch()
    by_id = dev / "serial" / "by-id" / "usb-FTDI_USB-RS485_Cable_FT1ABCD-if00-port0"
    by_id.symlink_to("../../ttyUSB3")
    (dev / "serial" / "by-path" / "pci-0000:00:14.0-usb-0:2:1.0-port0").symlink_to("../../ttyUSB3")
    (dev / "serial" / "by-id" / "usb-Acme_RS485-if00").symlink_to("../../ttyACM0")
    drivers = sysfs / "bus" / "drivers"
    for driver in ("ftdi_sio", "cdc_acm", "serial8250"):
        (drivers / driver).mkdir(parents=True)
    for name, driver in (("ttyUSB3", "ftdi_sio"), ("ttyACM0", "cdc_acm"), ("ttyS0", "serial8250")):
        device = sysfs / "class" / "tty" / name / "device"
        device.mkdir(parents=True)
        (device / "driver").symlink_to(drivers / driver)
    (sysfs / "class" / "tty" / "ttyUSB3" / "device" / "latency_timer").write_text("16\n")
    ports = [
        FakePort(str(dev / "ttyUSB3"), "ttyUSB3", "USB-RS485 Cable", 0x0403, 0x6001, "FT1ABCD",
                 "FTDI", "USB-RS485 Cable"),
        FakePort(str(dev / "ttyACM0"), "ttyACM0", "RS485", 0x1234, 0x0001, None, "Acme", None),
        FakePort(str(dev / "ttyS0"), "ttyS0"),
    ]  # fmt: skip
    return dev, sysfs, ports


def test_each_adapter_gets_its_by_id_name_driver_and_latency(tmp_path: Path) -> None:
    dev, sysfs, ports = machine(tmp_path)
    found = {a.device: a for a in describe(ports, dev=dev, sysfs=sysfs)}
    ftdi = found[str(dev / "ttyUSB3")]
    assert ftdi.stable_name == str(dev / "serial/by-id/usb-FTDI_USB-RS485_Cable_FT1ABCD-if00-port0")
    assert ftdi.by_path == (str(dev / "serial/by-path/pci-0000:00:14.0-usb-0:2:1.0-port0"),)
    assert (ftdi.usb_id, ftdi.serial_number, ftdi.driver) == ("0403:6001", "FT1ABCD", "ftdi_sio")
    assert ftdi.latency_timer_ms == 16
    acm = found[str(dev / "ttyACM0")]
    assert acm.stable_name.endswith("usb-Acme_RS485-if00")
    assert (acm.driver, acm.latency_timer_ms) == ("cdc_acm", None)
    uart = found[str(dev / "ttyS0")]
    assert (uart.stable_name, uart.by_id, uart.usb_id, uart.driver) == (
        str(dev / "ttyS0"), (), "", "serial8250"
    )  # fmt: skip


def test_the_table_names_the_stable_path_first_and_the_latency_cost(tmp_path: Path) -> None:
    dev, sysfs, ports = machine(tmp_path)
    text = format_table(describe(ports, dev=dev, sysfs=sysfs))
    blocks = text.split("\n\n")
    ftdi = next(b for b in blocks if "ttyUSB3" in b)
    assert ftdi.splitlines()[0].endswith("usb-FTDI_USB-RS485_Cable_FT1ABCD-if00-port0")
    assert "may change when replugged" in ftdi
    assert "16 ms" in ftdi and "latency timer to 1 ms" in ftdi
    assert "FT1ABCD" in ftdi and "0403:6001" in ftdi


def test_kernel_numbered_usb_names_are_unstable() -> None:
    assert unstable_name("/dev/ttyUSB0") and unstable_name("/dev/ttyACM1")
    assert not unstable_name("/dev/serial/by-id/usb-FTDI_x-if00-port0")
    assert not unstable_name("/dev/ttyS1") and not unstable_name("socket://gw:4001")


def test_ports_json_is_a_list_of_the_machine_s_ports() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "pkwbus", "ports", "--json"],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    listed = json.loads(done.stdout)
    from serial.tools import list_ports

    assert sorted(p["device"] for p in listed) == sorted(p.device for p in list_ports.comports())
    assert all(os.path.isabs(p["stable_name"]) for p in listed)
