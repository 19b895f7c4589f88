"""Built-in parameter tables of the simulated drives (until catalogs exist).

Numbers, types and conversion indexes follow the Danfoss FC 102/302 and
SINAMICS G120 lists where we know them; where a guide disagrees or is silent
we chose and say so:

- FC 16-10 Power [kW]: i32 with conversion -2 (0.01 kW). Some FC guides list
  another index; a catalog will override it.
- FC 4-14 Motor Speed High Limit [Hz] is the simulated drive's maximum
  frequency (MAV 0x4000 = 100 % of it). The example telegram of the Danfoss FC 300
  Design Manual writes 1000 to it (100.0 Hz).
- FC 15-30 Alarm Log: Error Code is UInt8 on the drive; here u16.
- FC 15-30..15-32 Alarm Log (code, value, time): 10 entries, index 0 the newest, as a
  secondary source has it (unconfirmed by a vendor page). 15-31 Alarm Log: Value is i32
  and holds the output current at the trip in 0.01 A (an illustrative choice; the
  drive's value depends on the alarm). 15-32 Alarm Log: Time is u32 and counts the
  drive's operating time in seconds at the trip: its unit and reference are not
  confirmed by any vendor document, and pkwbus never reads it as a time. The types of
  15-31 and 15-32 are unconfirmed.
- FC 15-00 Operating hours counts the hours the drive was powered, 15-01 Running Hours
  those it ran; 15-03 Power Up's: u32 (unconfirmed), counting the simulated drive's
  power-ups; 15-04 Over Temp's and 15-05 Over Volt's: u16 (unconfirmed), 0 (no fault
  injected here counts as either).
- USS r0039 Energy display: [0] balance and [1] drawn both the energy the model drew,
  [2] fed back 0 (the model never feeds back).
- USS fault buffer (SINAMICS S200 Operating Instructions, appendix A.3): r0947 Fault
  number u16 (as listed there), r0949 Fault value i32, r0948 and r2109 Fault time
  received / removed in ms u32, r2130 and r2136 the same in days u16: arrays of 64
  (8 fault cases x 8 faults). Only r0947's type is confirmed; the others' are not.
  r0944 Counter of fault buffer changes: u16 as the PROFIdrive profile's P944, not
  confirmed for SINAMICS. r2114 System runtime: [0] ms, [1] days, u32 (unconfirmed).
- USS alarm buffer (SINAMICS G120 parameter descriptions, r2121 to r2125): r2121
  Counter alarm buffer changes u16, r2122 Alarm code u16, r2124 Alarm value i32
  (as listed there), r2123 and r2125 time received / removed in ms u32, r2145 and
  r2146 the same in days u16 (the days' type unconfirmed): arrays of 64.
- USS MICROMASTER 4 (:data:`MM4_TABLE`, served with catalog ``siemens-mm4``): the USS
  table's readings and settings without the SINAMICS buffers, with the MICROMASTER 4
  fault buffer (:mod:`pkwbus.sim.drives.mm4`): r0947 u16 x 8, r0948 u16 x 12, r2114 u16 x 2
  and P2115 u16 x 3 (MICROMASTER 440 Parameter List 01/06: the types of r0948, r2114 and
  P2115; r0947's is not documented), r0949 u16 x 8 and P0952 u16 (neither's type or size
  documented: the simulator's choice). Which of the USS table's readings a MICROMASTER 4
  has under the same numbers is not confirmed (the simulator's choice).
- The log parameters carry no unit here: a catalog's unit for them then needs no
  conversion (they are counts, codes and times the model gives as they are).
- USS p0199 stands in for a text parameter (G120's p0199 is numeric).
- USS p2000 reference frequency scales MAV; p1082 limits the setpoint.
- Factory settings: a parameter's factory setting is its ``initial`` value; the drive
  answers it as FC description element 20 and says in PROFIdrive element 1 (bit 12)
  whether the value differs from it (:mod:`pkwbus.sim.drives.descriptions`).
- FC motor data (1-20..1-25, :data:`FC_MOTOR_DATA`) cannot change while the motor runs
  and depends on the power unit (FC 300 Design Guide MG.33.B3.22, "Additional
  characteristics (index 21)", bits 13 and 15); the table has 1-20 of them, a catalog
  may add the others.

``live`` names a quantity of the drive model (see ``model.py``); such a
parameter reads the model, never the store.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Final

from pkwbus.protocol.buses import Bus
from pkwbus.protocol.values import Scaling, ValueType

__all__ = [
    "CATALOG_TABLES",
    "FC_MOTOR_DATA",
    "FC_TABLE",
    "MM4_TABLE",
    "MODEL_PARAMS",
    "TABLES",
    "USS_TABLE",
    "Initial",
    "ParamSpec",
]

Initial = float | str | tuple[float, ...]


@dataclass(frozen=True, slots=True)
class ParamSpec:
    """How one parameter of a simulated drive behaves: its initial value, the model
    quantity it reads (``live``), whether it changes only while stopped, and the
    type, scaling, unit, limits and writability it answers with. Limits are
    engineering values. ``described``: False for a parameter whose description
    elements (AK 4) the drive refuses ("description not available").
    ``initial`` is also the factory setting. ``power_unit``: its values depend on the
    power unit (FC description element 21, bit 15).

    It describes the simulated drive, not what the master knows of a parameter
    (that is :class:`pkwbus.catalog.ParameterDescription`); a catalog's entries
    are merged into it by :mod:`pkwbus.sim.drives.catalogs`.
    """

    pnu: int
    name: str
    vtype: ValueType
    conversion: int = 0
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    writable: bool = False
    stopped_only: bool = False  # cannot change while the motor runs
    array: int = 0  # number of elements; 0 = not an array
    initial: Initial = 0
    live: str | None = None
    scale: float | None = None  # instead of the conversion index
    unit_factor: float = 1.0  # model units (table.py) -> this parameter's unit
    described: bool = True  # answers description requests (AK 4)
    power_unit: bool = False  # depends on the power unit (FC element 21, bit 15)

    @property
    def scaling(self) -> Scaling:
        if self.scale is not None:
            return Scaling.scale(self.scale)
        return Scaling.conversion(self.conversion)

    @property
    def elements(self) -> int:
        return self.array or 1


U16, I16, U32, I32, F32, TEXT = (
    ValueType.U16,
    ValueType.I16,
    ValueType.U32,
    ValueType.I32,
    ValueType.F32,
    ValueType.TEXT,
)

#: FC motor data, 1-20..1-25: changed only while the motor stands, power-unit dependent.
FC_MOTOR_DATA: Final = range(120, 126)

FC_TABLE: Final = (
    ParamSpec(120, "1-20", U32, -2, "kW", 0.09, 1000.0, True, True, initial=15.0, power_unit=True),
    ParamSpec(341, "3-41", U32, -2, "s", 0.01, 3600.0, True, initial=5.0),
    ParamSpec(342, "3-42", U32, -2, "s", 0.01, 3600.0, True, initial=5.0),
    ParamSpec(414, "4-14", U16, -1, "Hz", 0.0, 500.0, True, initial=50.0),
    ParamSpec(1500, "15-00", U32, 0, "h", live="operating_hours"),
    ParamSpec(1501, "15-01", U32, 0, "h", live="hours"),
    ParamSpec(1502, "15-02", U32, 0, "kWh", live="energy"),
    ParamSpec(1503, "15-03", U32, live="power_ups"),
    ParamSpec(1504, "15-04", U16),
    ParamSpec(1505, "15-05", U16),
    ParamSpec(1530, "15-30", U16, array=10, live="alarm_code"),
    ParamSpec(1531, "15-31", I32, array=10, live="alarm_value"),
    ParamSpec(1532, "15-32", U32, array=10, live="alarm_time"),
    ParamSpec(1540, "15-40", TEXT, writable=False, initial="FC-102"),
    ParamSpec(1543, "15-43", TEXT, writable=False, initial="05.11"),  # software version
    ParamSpec(1600, "16-00", U16, live="control_word"),
    ParamSpec(1603, "16-03", U16, live="status_word"),
    ParamSpec(1610, "16-10", I32, -2, "kW", live="power"),
    ParamSpec(1613, "16-13", U16, -1, "Hz", live="frequency"),
    ParamSpec(1614, "16-14", I32, -2, "A", live="current"),
    ParamSpec(1630, "16-30", U16, 0, "V", live="dc_link"),
    ParamSpec(1690, "16-90", U32, live="alarm_word"),
    ParamSpec(1692, "16-92", U32, live="warning_word"),
)

USS_TABLE: Final = (
    ParamSpec(21, "r0021", F32, 0, "Hz", live="frequency"),
    ParamSpec(24, "r0024", F32, 0, "Hz", live="frequency"),
    ParamSpec(25, "r0025", F32, 0, "V", live="output_voltage"),
    ParamSpec(26, "r0026", F32, 0, "V", live="dc_link"),
    ParamSpec(27, "r0027", F32, 0, "A", live="current"),
    ParamSpec(32, "r0032", F32, 0, "kW", live="power"),
    ParamSpec(39, "r0039", F32, 0, "kWh", array=3, live="energy"),
    ParamSpec(52, "r0052", U16, live="status_word"),
    ParamSpec(199, "p0199", TEXT, writable=True, initial="PUMP"),
    ParamSpec(304, "p0304", U16, 0, "V", 10.0, 2000.0, True, True, initial=400.0),
    # The fault buffer: 8 fault cases x 8 faults, [0..7] the active case.
    ParamSpec(944, "r0944", U16, live="fault_changes"),
    ParamSpec(947, "r0947", U16, array=64, live="fault_number"),
    ParamSpec(948, "r0948", U32, array=64, live="fault_received_ms"),
    ParamSpec(949, "r0949", I32, array=64, live="fault_value"),
    # Device identification: company (42), device type, firmware version (identity of a drive).
    ParamSpec(964, "r0964", U16, array=3, initial=(42.0, 1.0, 4710.0)),
    ParamSpec(1082, "p1082", F32, 0, "Hz", 0.0, 650.0, True, initial=50.0),
    ParamSpec(1120, "p1120", F32, 0, "s", 0.0, 650.0, True, initial=10.0),
    ParamSpec(1121, "p1121", F32, 0, "s", 0.0, 650.0, True, initial=10.0),
    ParamSpec(2000, "p2000", F32, 0, "Hz", 6.0, 650.0, True, initial=50.0),
    ParamSpec(2050, "r2050", U16, array=8, live="received_pzd"),
    ParamSpec(2109, "r2109", U32, array=64, live="fault_removed_ms"),
    ParamSpec(2114, "r2114", U32, array=2, live="runtime"),  # [0] ms, [1] days
    ParamSpec(2130, "r2130", U16, array=64, live="fault_received_days"),
    ParamSpec(2136, "r2136", U16, array=64, live="fault_removed_days"),
    # The alarm buffer: [0..7] the alarms there, [8..63] the history.
    ParamSpec(2121, "r2121", U16, live="alarm_changes"),
    ParamSpec(2122, "r2122", U16, array=64, live="buffered_alarm_code"),
    ParamSpec(2123, "r2123", U32, array=64, live="buffered_alarm_received_ms"),
    ParamSpec(2124, "r2124", I32, array=64, live="buffered_alarm_value"),
    ParamSpec(2125, "r2125", U32, array=64, live="buffered_alarm_removed_ms"),
    ParamSpec(2145, "r2145", U16, array=64, live="buffered_alarm_received_days"),
    ParamSpec(2146, "r2146", U16, array=64, live="buffered_alarm_removed_days"),
)

# The SINAMICS buffers' parameters, which a MICROMASTER 4 does not have so.
_SINAMICS_BUFFERS = frozenset(
    (944, 947, 948, 949, 2109, 2114, 2130, 2136, 2121, 2122, 2123, 2124, 2125, 2145, 2146)
)
MM4_TABLE: Final = (
    *(spec for spec in USS_TABLE if spec.pnu not in _SINAMICS_BUFFERS),
    # The fault buffer: two faults per trip, four trips, [0]/[1] the recent trip.
    ParamSpec(947, "r0947", U16, array=8, live="mm4_fault_number"),
    ParamSpec(948, "r0948", U16, array=12, live="mm4_fault_time"),
    ParamSpec(949, "r0949", U16, array=8, live="mm4_fault_value"),
    ParamSpec(952, "P0952", U16, live="mm4_fault_count"),
    ParamSpec(2114, "r2114", U16, array=2, live="mm4_runtime"),  # seconds: high, low word
    ParamSpec(2115, "P2115", U16, 0, "", 0.0, 65535.0, True, array=3),  # the AOP's clock
)

# Which parameters steer the model: maximum frequency (MAV scale), ramp times.
MODEL_PARAMS: Final = MappingProxyType(
    {
        Bus.FC: {"max_frequency": 414, "ramp_up": 341, "ramp_down": 342},
        Bus.USS: {"max_frequency": 2000, "ramp_up": 1120, "ramp_down": 1121},
    }
)
TABLES: Final = MappingProxyType({Bus.FC: FC_TABLE, Bus.USS: USS_TABLE})
# A catalog whose drives hold other parameters than their protocol's table, by (protocol,
# catalog): the table its entries are merged over.
CATALOG_TABLES: Final = MappingProxyType({(Bus.USS, "siemens-mm4"): MM4_TABLE})
