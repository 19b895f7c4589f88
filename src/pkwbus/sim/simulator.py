"""The simulated line: many drives behind one end, addressing, broadcasts, mirrors, faults,
and values set at the drives' keypads (:meth:`Simulator.keypad`; at random with
``keypad_every``, :mod:`pkwbus.sim.drives.keypad`)."""

from __future__ import annotations

import random
import time
from collections.abc import Callable, Collection, Iterable

from pkwbus.protocol.buses import Bus, address_range, decode_adr, default_dialect
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.pkw.dialects import dialect as get_dialect
from pkwbus.protocol.serial.telegram import (
    PCD_WORDS_FC,
    BlockShape,
    Deframer,
    Telegram,
    fc_lengths,
    frame,
    uss_lengths,
)
from pkwbus.sim.config import SimFaults, SimTiming
from pkwbus.sim.drives import faults as inject
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.drives.keypad import RandomKeypad
from pkwbus.sim.drives.model import ModelConfig
from pkwbus.sim.drives.table import TABLES, ParamSpec
from pkwbus.sim.serving import ends
from pkwbus.sim.serving.ends import PtyEnd, TcpEnd
from pkwbus.sim.serving.stats import SimStats

__all__ = [
    "Clock",
    "Simulator",
    "check_refusing",
    "random_keypad",
]

Clock = Callable[[], float]


class Simulator:
    """Simulated drives on one line. ``handle`` is the in-process end (no timing).

    ``refuse_descriptions``: addresses of drives that answer every description
    request (AK 4) with the dialect's "description not available" fault.
    ``keypad_every``: on average once per that many seconds (of the clock, checked at
    each request) one drive that is not dead gets a setting changed at its keypad
    (:mod:`pkwbus.sim.drives.keypad`); None: never.
    Raises ValueError for an address outside the protocol's range, one in
    ``refuse_descriptions`` that is not among ``addresses``, or a ``keypad_every`` that
    is not above 0.
    """

    def __init__(
        self,
        protocol: str,
        addresses: Iterable[int],
        *,
        dialect: str | None = None,
        ind_layout: IndLayout | None = None,
        pkw_words: int | None = None,  # USS: variable (127), as Siemens drives leave the factory
        pzd_words: int = 2,
        timing: SimTiming | None = None,
        faults: SimFaults | None = None,
        seed: int | None = None,
        catalog: str | None = None,
        clock: Clock = time.monotonic,
        model: ModelConfig | None = None,
        specs: tuple[ParamSpec, ...] | None = None,
        refuse_descriptions: Collection[int] = (),
        keypad_every: float | None = None,
    ) -> None:
        self.protocol = Bus(protocol)
        self.dialect = get_dialect(dialect or default_dialect(self.protocol))
        self.layout = ind_layout or self.dialect.default_ind_layout
        if self.protocol is Bus.FC:
            self.shape = BlockShape(None, PCD_WORDS_FC)
            self.lengths = fc_lengths()
        else:
            self.shape = BlockShape(pkw_words, pzd_words)
            self.lengths = uss_lengths([self.shape])
        self.timing = timing or SimTiming()
        self.faults = faults or SimFaults()
        self.clock = clock
        self.rng = random.Random(seed)
        self.stats = SimStats(sorted(set(addresses)))
        self._drive_faults: dict[int, SimFaults] = {}
        self._dead = set(self.faults.dead)
        table = specs if specs is not None else _specs(self.protocol, catalog)
        refusing = frozenset(refuse_descriptions)
        check_refusing(refusing, self.stats.drives)
        self.drives: dict[int, SimDrive] = {}
        for address in self.stats.drives:
            self._check_address(address)
            rng = random.Random(None if seed is None else seed * 1000 + address)
            self.drives[address] = SimDrive(
                address, self.protocol, self.dialect, self.layout, self.shape,
                table, self.timing, rng, model,
                described=address not in refusing,
            )  # fmt: skip
            self.drives[address].model.now = clock()
        self.random_keypad = random_keypad(keypad_every, seed, clock())

    def _check_address(self, address: int) -> None:
        low, top = address_range(self.protocol)
        if not low <= address <= top:
            raise ValueError(
                f"{self.protocol.value} drive address {address} is outside {low}-{top}"
            )

    # ------------------------------------------------------------ faults

    def set_faults(self, address: int, faults: SimFaults | None) -> None:
        """Faults for one drive instead of the line's (None: the line's again)."""
        if faults is None:
            self._drive_faults.pop(address, None)
        else:
            self._drive_faults[address] = faults

    def faults_for(self, address: int) -> SimFaults:
        return self._drive_faults.get(address, self.faults)

    def kill(self, address: int) -> None:
        self._dead.add(address)

    def revive(self, address: int) -> None:
        self._dead.discard(address)

    def is_dead(self, address: int) -> bool:
        """Dead by :meth:`kill` or the line's ``dead`` (both in ``_dead``), or by its own faults."""
        own = self._drive_faults.get(address)
        return address in self._dead or (own is not None and address in own.dead)

    # ------------------------------------------------------- drive events

    def trip(self, address: int, code: int, *, value: int | None = None) -> None:
        """Drive ``address`` trips now with fault (alarm) ``code`` (1-65535), as the random
        trips do; ``value`` (a signed 32-bit number) for its log entries, by default the
        output current at the trip in 0.01 A. The reset after ``trip_reset_seconds``
        follows as for a random trip. ValueError for an unknown drive or a code or value
        out of range."""
        if not 1 <= code <= 0xFFFF:
            raise ValueError(f"fault code {code} is outside 1-65535")
        if value is not None and not -(1 << 31) <= value < 1 << 31:
            raise ValueError(f"fault value {value} does not fit a signed 32-bit number")
        self._drive(address).trip(code, self.clock(), value=value)

    def warn(self, address: int, bit: int | None) -> None:
        """Drive ``address`` warns now with bit ``bit`` (0-31) of its warning word, the
        warning there before going; None: the warning goes. A SINAMICS drive enters the
        bit's alarm in its alarm buffer (r2122), and moves it into the history as it goes.
        ValueError for an unknown drive or a bit out of range."""
        if bit is not None and not 0 <= bit < 32:
            raise ValueError(f"warning bit {bit} is outside 0-31")
        self._drive(address).warn(bit, self.clock())

    def acknowledge(self, address: int) -> None:
        """The trip of drive ``address`` is acknowledged now (a local operator's reset)."""
        self._drive(address).acknowledge(self.clock())

    def power_cycle(self, address: int, off: float = 0.0) -> None:
        """Drive ``address`` is switched off now and on again ``off`` seconds later (0: at
        once), answering nothing meanwhile: a SINAMICS runtime (r2114) starts again from 0,
        a MICROMASTER 4 run time counter (r2114) goes on from where it stood, neither
        counting while it is off; it counts one more power-up (15-03); its logs are kept."""
        self._drive(address).power_cycle(self.clock(), off)

    def keypad(self, address: int, pnu: int, raw: int, index: int = 0) -> None:
        """A person at the keypad (LCP) of drive ``address`` sets element ``index`` of
        ``pnu`` to ``raw`` (the number as on the wire, a float's bits) now: in RAM and
        EEPROM, with no telegram; logged. ValueError with a plain message for an unknown
        drive or parameter, one the keypad cannot set (read-only, a live value, a text),
        an index or raw number the parameter does not have, a value outside its limits,
        and, while the motor runs, a parameter that cannot change while it runs (FC
        motor data, p0304)."""
        drive = self._drive(address)
        drive.tick(self.clock())
        drive.keypad(pnu, raw, index)

    def _keypad_at_random(self, now: float) -> None:
        chance = self.random_keypad
        if chance is not None and chance.due(now):
            alive = [d for a, d in self.drives.items() if not self.is_dead(a)]
            chance.change(now, alive)

    def _drive(self, address: int) -> SimDrive:
        drive = self.drives.get(address)
        if drive is None:
            raise ValueError(f"no simulated drive at address {address}")
        return drive

    # -------------------------------------------------------------- ends

    async def serve_tcp(self, host: str = "127.0.0.1", port: int = 0) -> TcpEnd:
        """Serve the line on TCP (raw telegram bytes); ``.url`` is a pyserial URL."""
        return await ends.serve_tcp(self, host, port)

    async def serve_pty(self, link: str) -> PtyEnd:
        """Serve the line on a new pseudo-terminal reachable at the symlink ``link``."""
        return await ends.serve_pty(self, link)

    # --------------------------------------------------------- telegrams

    def deframer(self) -> Deframer:
        """A deframer for requests on this line (one per connection)."""
        return Deframer(self.lengths)

    def is_request(self, event: object) -> bool:
        return isinstance(event, Telegram)

    def request_size(self, event: object) -> int:
        assert isinstance(event, Telegram)
        return len(event.data) + 4  # STX, LGE, ADR and BCC around the data

    def handle(self, request: bytes) -> bytes | None:
        """One request telegram in, the answer out (None: silence). No timing."""
        events = self.deframer().feed(request)
        telegram = next((e for e in events if isinstance(e, Telegram)), None)
        if telegram is None:
            self.stats.count("bad_requests")
            return None
        answer = self.answer(telegram)
        return answer.data if answer else None

    def answer(self, telegram: Telegram, now: float | None = None) -> Answer | None:
        """What the line answers to a deframed request, faults applied."""
        now = self.clock() if now is None else now
        self._keypad_at_random(now)
        stats = self.stats
        stats.count("requests")
        adr = decode_adr(self.protocol, telegram.adr)
        if adr.special:
            stats.count("ignored")
            return None
        if adr.broadcast:
            self._broadcast(telegram, now)
            return None
        drive = self.drives.get(adr.address)
        if drive is None:
            stats.count("ignored")
            return None
        if self.is_dead(drive.address) or drive.off(now):
            stats.inject("dead", drive.address)  # switched off: as dead
            return None
        clean = telegram.encode() if adr.mirror else self._respond(drive, telegram, now)
        if clean is None:
            return None
        return self._send(drive, clean)

    def _respond(self, drive: SimDrive, telegram: Telegram, now: float) -> bytes | None:
        self.stats.count_drive(drive.address, "requests")
        data = self._drive_respond(drive, telegram.data, now, broadcast=False)
        return None if data is None else frame(telegram.adr, data)

    def _broadcast(self, telegram: Telegram, now: float) -> None:
        """Every live drive applies a broadcast; none answers."""
        self.stats.count("broadcasts")
        for drive in self.drives.values():
            if not self.is_dead(drive.address):
                self._drive_respond(drive, telegram.data, now, broadcast=True)

    def _drive_respond(
        self, drive: SimDrive, data: bytes, now: float, *, broadcast: bool
    ) -> bytes | None:
        drive.tick(now)
        taken, lagged = drive.control_taken, drive.lagged
        try:
            out = drive.respond(data, now, broadcast=broadcast)
        except RemoteProtocolError:
            self.stats.count("malformed", drive.address)
            return None
        self.stats.count("control_taken", drive.address, drive.control_taken - taken)
        self.stats.count("lagged", drive.address, drive.lagged - lagged)
        return out

    def _send(self, drive: SimDrive, clean: bytes) -> Answer | None:
        kind = inject.pick(self.faults_for(drive.address), self.rng)
        if kind == "stale" and drive.last_answer is None:
            kind = None
        stale = drive.last_answer
        drive.last_answer = clean
        if kind is None:
            answer: Answer | None = Answer(clean)
        else:
            self.stats.inject(kind, drive.address)
            answer = inject.apply(
                kind, clean, stale=stale, faults=self.faults_for(drive.address),
                protocol=self.protocol, rng=self.rng,
            )  # fmt: skip
        if answer is not None:
            self.stats.count("responses", drive.address)
        return answer


def check_refusing(refusing: Collection[int], drives: Collection[int]) -> None:
    """ValueError when an address that is to refuse descriptions is not a simulated drive."""
    strangers = sorted(set(refusing) - set(drives))
    if strangers:
        names = ", ".join(str(a) for a in strangers)
        raise ValueError(f"refuse descriptions: no simulated drive at address {names}")


def random_keypad(every: float | None, seed: int | None, now: float) -> RandomKeypad | None:
    """The random keypad changes of a line (None: none), with a generator of their own
    (so that they leave the line's fault draws as they are), seeded from ``seed``."""
    if every is None:
        return None
    return RandomKeypad(every, random.Random(None if seed is None else f"keypad {seed}"), now)


def _specs(protocol: Bus, catalog: str | None) -> tuple[ParamSpec, ...]:
    if catalog is not None:
        from pkwbus.sim.drives.catalogs import specs_from_catalog

        return specs_from_catalog(protocol, catalog)
    return TABLES[protocol]
