"""The live list of a PROFIBUS DP line under the runner: which stations answer, and what.

After the port listens for other masters (none may be active), every address
asked in turn for its FDL status (EN 50170 vol. 2 part 4, "FDL status"): the
answer says whether a station is there and whether it is a slave or a
master. Each slave is then asked its diagnosis (Slave_Diag): ident number,
state, and the master that owns it. Nothing is parametrised, and the port
closes without Global_Control Clear. Each request is repeated up to
``tries`` times while no answer comes, as the FDL repeats a request.

Pure calls, holding no port (:class:`~pkwbus.master.runner.Wire`; it is given
the master's address, the station its requests come from): what it found is among its
events (:class:`~pkwbus.master.events.StationFound`), and its end too
(:class:`~pkwbus.master.events.StationsAsked`).
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from pkwbus.master.events import Event, StationAsked, StationFound, StationsAsked
from pkwbus.master.planning.plan import Idle
from pkwbus.master.planning.planner import IDLE_AT_MOST, Planner
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.slave import Answer
from pkwbus.protocol.profibus.fdl import DataFrame, StationType

__all__ = ["LiveListWire"]

# Seconds a request's repeats may take at most: the FDL's own, a slot time each.
_POLL_DEADLINE = 5.0


class _Asking(enum.Enum):
    STATUS = "FDL status"
    DIAGNOSIS = "Slave_Diag"


class LiveListWire:
    """The :class:`~pkwbus.master.runner.Wire` of a DP line's live list."""

    def __init__(self, master: int, addresses: Sequence[int], *, tries: int) -> None:
        self.master = master  # the line's master address: its requests' source
        self.addresses = list(addresses)
        self.tries = tries
        self._place = 0  # the station asked now, in ``addresses``
        self._asking = _Asking.STATUS
        self._tried = 0  # requests to it so far, in this phase
        self._told = -1  # the place whose asking was told
        self._station = StationType.SLAVE
        self._events: list[Event] = []
        self._over = False

    def poll_deadline(self, retries: int) -> float:
        return _POLL_DEADLINE

    def transmit(self, planner: Planner, now: float) -> DataFrame | Idle:
        if self._place >= len(self.addresses):
            if not self._over:
                self._over = True
                self._events.append(StationsAsked())
            return Idle(now + IDLE_AT_MOST)
        address = self.addresses[self._place]
        if self._told != self._place:
            self._told = self._place
            self._events.append(StationAsked(address, self._place + 1, len(self.addresses)))
        master = self.master
        if self._asking is _Asking.STATUS:
            return DataFrame(address, master, fdl.request_fc(fdl.Function.FDL_STATUS))
        return dps.request(dps.Service.SLAVE_DIAG, address, master, fcb=True, fcv=False)

    def received(
        self, planner: Planner, request: DataFrame, answer: Answer, now: float, busy: float,
        answered: float,
    ) -> None:  # fmt: skip
        address = request.da
        if not isinstance(answer, DataFrame):  # none, garbled, or a short acknowledge
            self._tried += 1
            if self._tried >= self.tries:
                if self._asking is _Asking.DIAGNOSIS:  # there, but no diagnosis
                    self._events.append(StationFound(address, StationType.SLAVE))
                self._next()
            return
        if self._asking is _Asking.STATUS:
            if answer.control.is_request:  # not an answer: nobody there
                self._next()
                return
            kind = answer.control.station_type or StationType.SLAVE
            if kind is not StationType.SLAVE:
                self._events.append(StationFound(address, kind))
                self._next()
                return
            self._asking, self._tried = _Asking.DIAGNOSIS, 0
            return
        try:
            diagnosis: dps.Diagnosis | None = dps.decode_diagnosis(answer.data)
        except RemoteProtocolError:
            diagnosis = None
        self._events.append(StationFound(address, StationType.SLAVE, diagnosis))
        self._next()

    def lost(self) -> None:
        """The port was lost: the station asked is asked again from the start."""
        self._asking, self._tried = _Asking.STATUS, 0

    def leave_out(self, planner: Planner, drive: str, out: bool, now: float) -> None:
        """Nothing to do: the planner gives a drive in maintenance no exchange (one that
        is out ends at its answer or timeout, as every exchange)."""

    def take_events(self) -> list[Event]:
        events, self._events = self._events, []
        return events

    def _next(self) -> None:
        self._place += 1
        self._asking, self._tried = _Asking.STATUS, 0
