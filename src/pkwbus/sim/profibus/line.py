"""Simulated PROFIBUS DP slaves on one line: drives behind their DP-V0 state machines.

Each slave is a :class:`~pkwbus.sim.profibus.slave.SimDpSlave` around a simulated
drive (:class:`~pkwbus.sim.drives.drive.SimDrive`): Set_Prm, Chk_Cfg, diagnosis and
the watchdog as a DP slave does them, and in data exchange the PPO-write's
PKW request answered from the drive's parameters in the PPO-read, with its
status word and main actual value. The dialect decides the drive's
parameters: ``danfoss-pcv`` serves Danfoss FC parameters (catalog
``danfoss-fc``), ``profidrive`` Siemens ones (``siemens-g120``),
``hitachi-sjpb`` the built-in table.

Faults, drawn per answer as on FC and USS lines: ``drop`` (no answer),
``corrupt`` (a wrong FCS), ``garbage`` (noise before the frame), ``late``,
``stale`` (the previous answer again), and the DP ones: ``rs`` (the slave
answers "SAP not activated", as one that fell out of data exchange) and
``restart`` (the slave power-cycles: parameters and configuration lost).

A slave's drive may keep a PROFIdrive fault buffer of a given shape and P948 type
(``fault_buffers``: :mod:`pkwbus.sim.drives.profidrive_buffer`), answered through its
PPO's PKW words and data record 47 ahead of the dialect's parameters of those numbers.

A person at a slave drive's keypad (LCP) may set a value with no telegram
(:meth:`DpSimulator.keypad`), and with ``keypad_every`` one does so at random, as on
FC and USS lines (:mod:`pkwbus.sim.drives.keypad`).

Raises: :class:`ValueError` for an address outside 0-125, a dialect or PPO
PROFIBUS does not have.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable, Collection, Iterable, Mapping
from dataclasses import dataclass, field

from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.pkw import PkwRequest, PkwResponse
from pkwbus.protocol.pkw.dialects import IndLayout
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.fdl import BROADCAST, DataFrame, Status
from pkwbus.protocol.profidrive.parameters import AXES, ParameterAddress, ParameterError, Values
from pkwbus.protocol.serial.telegram import BlockShape
from pkwbus.sim.config import SimFaults, SimTiming
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.faults import Answer
from pkwbus.sim.drives.model import ModelConfig
from pkwbus.sim.drives.profidrive_buffer import BufferKind, ProfidriveFaultBuffer
from pkwbus.sim.drives.table import TABLES, ParamSpec
from pkwbus.sim.profibus.records import Own, RecordServer
from pkwbus.sim.profibus.slave import SimDpSlave
from pkwbus.sim.serving import ends
from pkwbus.sim.serving.ends import PtyEnd, TcpEnd
from pkwbus.sim.serving.stats import SimStats
from pkwbus.sim.simulator import check_refusing, random_keypad

__all__ = ["DEFAULT_IDENTS", "DP_FAULT_KINDS", "DpFaults", "DpSimulator", "SlaveKind"]

Clock = Callable[[], float]

MAX_ADDRESS = 125  # DP slave addresses 0-125 (126 is for commissioning, 127 broadcast)

# The parameters each dialect's drive holds, and its catalog by default.
DRIVE_PROTOCOL = {
    "danfoss-pcv": Bus.FC,
    "profidrive": Bus.USS,
    "hitachi-sjpb": Bus.USS,
}
DEFAULT_CATALOGS = {"danfoss-pcv": "danfoss-fc", "profidrive": "siemens-g120", "hitachi-sjpb": None}
# Ident numbers the simulated slaves report (a real drive's is in its GSD file).
DEFAULT_IDENTS = {"danfoss-pcv": 0x0402, "profidrive": 0x80B5, "hitachi-sjpb": 0x0B6A}

DP_FAULT_KINDS = ("drop", "corrupt", "garbage", "late", "stale", "rs", "restart")


@dataclass(frozen=True)
class DpFaults:
    """Probabilities (0..1) of a fault per answer, the dead slaves and the late delay."""

    drop: float = 0.0
    corrupt: float = 0.0
    garbage: float = 0.0
    late: float = 0.0
    stale: float = 0.0
    rs: float = 0.0
    restart: float = 0.0
    late_seconds: float = 1.0
    dead: frozenset[int] = field(default_factory=frozenset)

    def __post_init__(self) -> None:
        total = sum(getattr(self, kind) for kind in DP_FAULT_KINDS)
        if any(not 0.0 <= getattr(self, kind) <= 1.0 for kind in DP_FAULT_KINDS):
            raise ValueError("a fault probability is outside 0..1")
        if total > 1.0 + 1e-9:
            raise ValueError(f"fault probabilities add up to {total:.3f}, more than 1")

    @classmethod
    def from_sim_faults(cls, faults: SimFaults) -> DpFaults:
        """The faults of ``pkwbus simulate`` that a DP line has too."""
        return cls(
            drop=faults.drop, corrupt=faults.corrupt, garbage=faults.garbage,
            late=faults.late, stale=faults.stale, late_seconds=faults.late_seconds,
            dead=faults.dead,
        )  # fmt: skip


@dataclass(frozen=True, slots=True)
class SlaveKind:
    """One simulated slave's dialect, ident number (None: the dialect's) and catalog."""

    dialect: str
    ident: int | None = None
    catalog: str | None = "default"


class DpSimulator:
    """Simulated DP slaves on one line; the ends serve it on a pty or TCP."""

    def __init__(
        self,
        addresses: Iterable[int],
        *,
        dialect: str = "profidrive",
        ppo_number: int = 1,
        ident: int | None = None,
        timing: SimTiming | None = None,
        faults: DpFaults | None = None,
        seed: int | None = None,
        catalog: str | None = "default",
        clock: Clock = time.monotonic,
        each: Mapping[int, SlaveKind] | None = None,
        model: ModelConfig | None = None,
        refuse_descriptions: Collection[int] = (),
        dpv1: bool = False,
        not_ready: int = 0,
        keypad_every: float | None = None,
        fault_buffers: Mapping[int, BufferKind] | None = None,
    ) -> None:
        """``dpv1``: the slaves whose dialect has parameter access (data record 47) run
        DP-V1 when parametrised so, answering ``not_ready`` reads of each response with
        "state conflict" first; ``each``: slaves of another dialect, ident or catalog
        than the line's, by address;
        ``refuse_descriptions``: slaves whose drives answer every description request (AK 4)
        with the dialect's "description not available" fault (ValueError for an address
        that is not a slave here); ``keypad_every``: on average once per that many
        seconds one slave's drive that is not dead gets a setting changed at its keypad
        (ValueError when it is not above 0); ``fault_buffers``: slaves whose drives keep
        a PROFIdrive fault buffer of that kind (ValueError for one that is not a slave
        here)."""
        if not_ready < 0:
            raise ValueError(f"not ready for {not_ready} reads: it cannot be negative")
        try:
            self.dialect = ppo.dp_dialect(dialect)
            self.ppo = ppo.ppo_type(ppo_number)
            for kind in (each or {}).values():
                ppo.dp_dialect(kind.dialect)
        except LocalProtocolError as exc:
            raise ValueError(str(exc)) from None
        self.protocol = "profibus"
        self.timing = timing or SimTiming()
        self.faults = faults or DpFaults()
        self.clock = clock
        self.rng = random.Random(seed)
        self.ident = DEFAULT_IDENTS[dialect] if ident is None else ident
        self.stats = SimStats(sorted(set(addresses)))
        shape = BlockShape(self.ppo.pkw_words, self.ppo.pzd_words)
        self.drives: dict[int, SimDrive] = {}
        self.slaves: dict[int, SimDpSlave] = {}
        self.records: dict[int, RecordServer | None] = {}
        self._last: dict[int, bytes] = {}
        line_kind = SlaveKind(dialect, self.ident, catalog)
        refusing = frozenset(refuse_descriptions)
        check_refusing(refusing, self.stats.drives)
        buffers = dict(fault_buffers or {})
        if not buffers.keys() <= set(self.stats.drives):
            raise ValueError(f"fault buffers of slaves not here: {sorted(buffers)}")
        for address in self.stats.drives:
            if not 0 <= address <= MAX_ADDRESS:
                raise ValueError(f"profibus slave address {address} is outside 0-{MAX_ADDRESS}")
            kind = (each or {}).get(address, line_kind)
            name = kind.dialect
            drive_protocol = DRIVE_PROTOCOL[name]
            specs = _specs(
                drive_protocol,
                DEFAULT_CATALOGS[name] if kind.catalog == "default" else kind.catalog,
            )
            rng = random.Random(None if seed is None else seed * 1000 + address)
            drive = SimDrive(
                address, drive_protocol, ppo.dp_dialect(name), IndLayout.PROFIDRIVE, shape, specs,
                self.timing, rng, model, described=address not in refusing,
            )  # fmt: skip
            drive.model.now = clock()
            self.drives[address] = drive
            ident_number = DEFAULT_IDENTS[name] if kind.ident is None else kind.ident
            axis = AXES.get(name)
            own = _keep_buffer(drive, buffers[address]) if address in buffers else None
            records = (
                RecordServer(drive.params, drive.dialect, axis, own) if axis is not None else None
            )
            self.records[address] = records
            self.slaves[address] = SimDpSlave(
                address, ident_number, self.ppo.cfg, drive.respond,
                records=records.answer if records is not None and dpv1 else None,
                not_ready=not_ready,
            )  # fmt: skip
        self.random_keypad = random_keypad(keypad_every, seed, clock())

    # ------------------------------------------------------------ faults

    def kill(self, address: int) -> None:
        self.faults = _with_dead(self.faults, self.faults.dead | {address})

    def revive(self, address: int) -> None:
        self.faults = _with_dead(self.faults, self.faults.dead - {address})

    def lock(self, address: int, master: int) -> None:
        """Another master (station ``master``) takes the slave: locked to it."""
        self.slaves[address].lock_to(master)

    def release(self, address: int) -> None:
        """The other master lets the slave go."""
        self.slaves[address].release()

    def keypad(self, address: int, pnu: int, raw: int, index: int = 0) -> None:
        """A person at the keypad (LCP) of the drive of slave ``address`` sets element
        ``index`` of ``pnu`` to ``raw`` now, as :meth:`Simulator.keypad
        <pkwbus.sim.simulator.Simulator.keypad>` does (ValueError alike)."""
        drive = self.drives.get(address)
        if drive is None:
            raise ValueError(f"no simulated slave at address {address}")
        drive.tick(self.clock())
        drive.keypad(pnu, raw, index)

    def restart(self, address: int) -> None:
        """Power-cycle a slave: its DP parameters and configuration are lost."""
        self.slaves[address]._reset()
        self.stats.inject("restart", address)

    # ------------------------------------------------------- for the ends

    def deframer(self) -> fdl.Deframer:
        return fdl.Deframer()

    def is_request(self, event: object) -> bool:
        return isinstance(event, fdl.Frame)

    def request_size(self, event: object) -> int:
        assert isinstance(event, fdl.Frame)
        return len(fdl.encode(event))

    async def serve_tcp(self, host: str = "127.0.0.1", port: int = 0) -> TcpEnd:
        return await ends.serve_tcp(self, host, port)

    async def serve_pty(self, link: str) -> PtyEnd:
        return await ends.serve_pty(self, link)

    # ------------------------------------------------------------ frames

    def handle(self, request: bytes) -> bytes | None:
        """One request frame in, the answer out (None: silence). No timing."""
        frames = [e for e in fdl.Deframer().feed(request) if isinstance(e, fdl.Frame)]
        if not frames:
            self.stats.count("bad_requests")
            return None
        answer = self.answer(frames[0])
        return answer.data if answer else None

    def answer(self, frame: object, now: float | None = None) -> Answer | None:
        """What the line answers to a deframed request frame, faults applied."""
        now = self.clock() if now is None else now
        chance = self.random_keypad
        if chance is not None and chance.due(now):
            alive = [d for a, d in self.drives.items() if a not in self.faults.dead]
            chance.change(now, alive)
        if not isinstance(frame, DataFrame) or not frame.control.is_request:
            self.stats.count("ignored")
            return None
        self.stats.count("requests")
        if frame.da == BROADCAST:
            self.stats.count("broadcasts")
            for each in self.slaves.values():
                each.handle(frame, now)
            return None
        slave = self.slaves.get(frame.da)
        if slave is None:
            self.stats.count("ignored")
            return None
        if frame.da in self.faults.dead:
            self.stats.inject("dead", frame.da)
            return None
        self.stats.count_drive(frame.da, "requests")
        self.drives[frame.da].tick(now)
        kind = self._pick()
        if kind == "restart":
            self.restart(frame.da)
            kind = None
        try:
            reply = slave.handle(frame, now)
        except RemoteProtocolError:
            self.stats.count("malformed", frame.da)
            return None
        if reply is None:
            return None
        if kind == "rs":
            kind = None  # the short acknowledge has no status to set: nothing injected
            if isinstance(reply, DataFrame):
                self.stats.inject("rs", frame.da)
                reply = DataFrame(
                    reply.da, reply.sa, fdl.response_fc(Status.RS), reply.dsap, reply.ssap
                )
        clean = fdl.encode(reply)
        return self._send(frame.da, clean, kind)

    def _pick(self) -> str | None:
        draw = self.rng.random()
        for kind in DP_FAULT_KINDS:
            p = float(getattr(self.faults, kind))
            if draw < p:
                return kind
            draw -= p
        return None

    def _send(self, address: int, clean: bytes, kind: str | None) -> Answer | None:
        stale = self._last.get(address)
        self._last[address] = clean
        if kind == "corrupt" and len(clean) <= 2:
            kind = None  # the short acknowledge has no FCS to get wrong: nothing injected
        if kind is not None:
            self.stats.inject(kind, address)
        if kind == "drop":
            return None
        self.stats.count("responses", address)
        if kind == "late":
            return Answer(clean, self.faults.late_seconds)
        if kind == "stale":
            return Answer(stale if stale is not None else clean)
        if kind == "corrupt":
            # The FCS is the byte before the end delimiter.
            wrong = clean[-2] ^ self.rng.randrange(1, 256)
            return Answer(clean[:-2] + bytes((wrong,)) + clean[-1:])
        if kind == "garbage":
            noise = bytes(self.rng.randrange(0x20, 0x60) for _ in range(self.rng.randrange(1, 6)))
            return Answer(noise + clean)
        return Answer(clean)


def _with_dead(faults: DpFaults, dead: frozenset[int]) -> DpFaults:
    from dataclasses import replace

    return replace(faults, dead=frozenset(dead))


def _specs(protocol: Bus, catalog: str | None) -> tuple[ParamSpec, ...]:
    if catalog is not None:
        from pkwbus.sim.drives.catalogs import specs_from_catalog

        return specs_from_catalog(protocol, catalog)
    return TABLES[protocol]


def _keep_buffer(drive: SimDrive, kind: BufferKind) -> Own:
    """``drive`` keeps a PROFIdrive fault buffer of ``kind``, answered through its PKW
    channel; what answers it through data record 47."""
    buffer = ProfidriveFaultBuffer(kind)
    drive.model.profidrive = buffer
    params = drive.params

    def pkw_answer(req: PkwRequest) -> PkwResponse | None:
        return buffer.answer_pkw(req, params.dialect, params.faults, drive.model.powered_ms)

    def record_answer(address: ParameterAddress) -> Values | ParameterError | None:
        return buffer.answer_record(address, params.faults, drive.model.powered_ms)

    params.ahead = pkw_answer
    return record_answer
