"""The ways a PKW job travels, one carrier each (:class:`~pkwbus.master.planning.carrier.Carrier`):
a serial telegram (FC, USS), a PPO's PKW slot (PROFIBUS DP), PROFIdrive data record 47
(DP-V1). Each encodes a job's request and decodes its answer, once; the planner
above them never knows the bus.
"""

from __future__ import annotations

from pkwbus.master.carriers.record import RecordCarrier
from pkwbus.master.carriers.serial import SerialCarrier
from pkwbus.master.carriers.slot import SlotCarrier
from pkwbus.master.planning.carrier import Carrier
from pkwbus.master.target import DriveTarget
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus.dp.ppo import PPO_TYPES

__all__ = ["RecordCarrier", "SerialCarrier", "SlotCarrier", "carrier_for"]


def carrier_for(target: DriveTarget) -> Carrier:
    """The carrier of a drive as the line addresses it."""
    if target.protocol is not Bus.PROFIBUS:
        return SerialCarrier(target)
    record = target.record
    if record is not None:
        return RecordCarrier(
            target.address, target.dialect, record.axis, record.max_data, record.slot
        )
    shape = target.shape
    for kind in PPO_TYPES.values():
        if (kind.pkw_words, kind.pzd_words) == (shape.pkw_words, shape.pzd_words):
            return SlotCarrier(target.address, kind, target.dialect)
    raise LocalProtocolError(f"no PPO type has {shape.pkw_words} PKW and {shape.pzd_words} PZD")
