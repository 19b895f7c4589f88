"""The only layer that touches a serial port: pyserial-asyncio for device paths and URLs."""

from pkwbus.link.eventloop import new_event_loop, run
from pkwbus.link.port import Link, LinkState, PortError, PortSettings

__all__ = ["Link", "LinkState", "PortError", "PortSettings", "new_event_loop", "run"]
