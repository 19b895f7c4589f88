"""The only layer that touches a serial port: pyserial-asyncio for device paths and URLs."""

from pkwbus.link.eventloop import new_event_loop, run
from pkwbus.link.fence import ALWAYS_OPEN, Fence
from pkwbus.link.ownership import PortBusy, same_line
from pkwbus.link.port import Link, PortError, PortSettings
from pkwbus.link.reconnect import LinkState, Reconnect
from pkwbus.link.serialport import closes_done

__all__ = [
    "ALWAYS_OPEN",
    "Fence",
    "Link",
    "LinkState",
    "PortBusy",
    "PortError",
    "PortSettings",
    "Reconnect",
    "closes_done",
    "new_event_loop",
    "run",
    "same_line",
]
