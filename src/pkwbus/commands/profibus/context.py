"""`pkwbus read`, `write` and `describe` with ``--protocol profibus``: pkwbus as DP master.

The slave goes through its start-up (Slave_Diag, Set_Prm, Chk_Cfg, Slave_Diag
until ready), then the job goes through the PKW part of its PPO until the
matching answer comes; with ``--access ds47`` (the default on a PPO without
PKW words) the slave is parametrised as a DP-V1 slave and the job goes as a
PROFIdrive parameter request in data record 47. Set_Prm carries the ident
number, the user parameters and the module identifiers given, or read from the
drive's GSD file. A slave
owned by another master is never parametrised (exit 3); a line another
master runs is never used (exit 3). At the end Global_Control Clear goes to
every slave and the port is closed.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad options,
an unreadable GSD file, a port that cannot be opened or a line another master runs.
"""

from __future__ import annotations

import argparse
import asyncio
from collections.abc import Sequence
from dataclasses import dataclass

from pkwbus.catalog import dp_settings
from pkwbus.catalog.dp_settings import DpGiven
from pkwbus.commands.common import CommandError, Exit, duration_option, int_option, print_trace
from pkwbus.link import PortError, PortSettings
from pkwbus.master.carriers import carrier_for
from pkwbus.master.events import (
    Event,
    LineState,
    SlaveDiagnosed,
    SlaveSilent,
    SlaveStateChanged,
)
from pkwbus.master.planning.outcomes import Outcome, TimedOut
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.sessions.session import EndKind, LineSession, SessionEnded
from pkwbus.master.target import DriveTarget, RecordAccess
from pkwbus.master.wires.profibus.cycle import SlaveLocked
from pkwbus.master.wires.profibus.port import FdlPort
from pkwbus.master.wires.profibus.refusal import OPTIONS, refusal
from pkwbus.master.wires.profibus.wire import CycleWire, SlaveSpec
from pkwbus.notation import durations, limits
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.profibus.dp import ppo
from pkwbus.protocol.profibus.dp import services as dps
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, PpoType
from pkwbus.protocol.profibus.dp.slave import SlaveSetup, SlaveState
from pkwbus.protocol.profibus.dpv1.msac import Dpv1Setup
from pkwbus.protocol.profibus.fdl import timing as dp_timing
from pkwbus.protocol.profibus.gsd import Gsd
from pkwbus.protocol.profidrive.parameters import AXES
from pkwbus.protocol.serial.telegram import BlockShape
from pkwbus.protocol.values.types import ValueType

__all__ = [
    "DEFAULT_BAUDRATE",
    "DEFAULT_DEADLINE",
    "DP_CATALOGS",
    "MAX_DP_RETRIES",
    "DpContext",
    "add_dp_options",
    "build_context",
    "fdl_port",
    "session",
]

DEFAULT_BAUDRATE = 19200
DEFAULT_DIALECT = "profidrive"
SLOT_TIME = durations.DP_SLOT_TIME
MAX_DP_RETRIES = 8
DEFAULT_DEADLINE = 2.0  # seconds for one job, the slave's start-up included
# The catalog each dialect's parameters are named and scaled by, when none is given.
DP_CATALOGS = {"danfoss-pcv": "danfoss-fc", "profidrive": "siemens-g120", "hitachi-sjpb": None}


def add_dp_options(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("PROFIBUS DP (--protocol profibus)")
    g.add_argument(
        "--master-address", type=int_option(0, 125), default=2, help="pkwbus's station (2)"
    )
    g.add_argument("--ppo", type=int_option(1, 5), default=1, help="PPO type 1-5 (default 1)")
    which = g.add_mutually_exclusive_group()
    which.add_argument("--ident", default=None, help="the slave's ident number, e.g. 0x0402")
    which.add_argument("--gsd", default=None, metavar="FILE", help="the drive's GSD file")
    g.add_argument("--cfg", default=None, help='configuration identifiers, e.g. "F3 F1"')
    g.add_argument("--user-prm", default=None, metavar="HEX", help="user parameter bytes")
    g.add_argument(
        "--access",
        choices=("pkw", "ds47"),
        default=None,
        help="parameters through the PPO's PKW words or PROFIdrive data record 47 over"
        " DP-V1 (default: pkw where the PPO has PKW words, else ds47)",
    )
    g.add_argument(
        "--axis",
        type=int_option(0, 255),
        default=None,
        help="the drive object of data record 47 (default: SINAMICS 1, Danfoss 0)",
    )
    g.add_argument(
        "--slot-time",
        type=duration_option(SLOT_TIME),
        default=None,
        help="how long an answer may take to start (default: 30ms at 19200, 8ms at 93750)",
    )


@dataclass(frozen=True)
class DpContext:
    """What a DP command needs: the dialect, the PPO, the Set_Prm parameters and cfg."""

    dialect: Dialect
    ppo: PpoType
    parameters: dps.Parameters
    cfg: bytes
    master: int
    retries: int
    record: RecordAccess | None = None  # parameters through data record 47 (DP-V1)
    dpv1: Dpv1Setup | None = None
    slot_time: float | None = None  # None: the default at the line's rate

    def setup(self, address: int) -> SlaveSetup:
        try:
            return SlaveSetup(
                address, self.master, self.parameters, self.cfg, self.retries, dpv1=self.dpv1
            )
        except LocalProtocolError as exc:
            raise CommandError(str(exc), Exit.BAD_INPUT) from None

    def target(self, address: int) -> DriveTarget:
        """The slave as the runner addresses it."""
        shape = BlockShape(self.ppo.pkw_words, self.ppo.pzd_words)
        try:
            return DriveTarget(
                Bus.PROFIBUS, address, self.dialect, ppo.LAYOUT, shape, record=self.record
            )
        except LocalProtocolError as exc:
            raise CommandError(str(exc), Exit.BAD_INPUT) from None

    def slot(self) -> PkwSlot:
        return PkwSlot(self.ppo, self.dialect)


def _hex_bytes(text: str, what: str) -> bytes:
    cleaned = text.replace(",", " ").replace("0x", "").replace("0X", "")
    try:
        return bytes.fromhex(cleaned)
    except ValueError:
        raise CommandError(f"{what}: {text[:40]!r} is not hex bytes", Exit.BAD_INPUT) from None


def _option(key: str) -> str:
    """A field of the DP settings as the command line names it."""
    return "--" + key.replace("_", "-")


def build_context(args: argparse.Namespace) -> DpContext:
    """The DP settings of a command; exit 2 for anything unusable, before any port is opened."""
    if args.parity != "E":
        raise CommandError("PROFIBUS characters are always 8E1: --parity E", Exit.BAD_INPUT)
    if args.retries > MAX_DP_RETRIES:
        raise CommandError(f"--retries: at most {MAX_DP_RETRIES} over PROFIBUS", Exit.BAD_INPUT)
    try:
        dia = ppo.dp_dialect(args.dialect or DEFAULT_DIALECT)
        kind = ppo.ppo_type(args.ppo)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    ident = None
    if args.ident is not None:
        try:
            ident = limits.check_int(int(args.ident, 0), 0, 0xFFFF)
        except ValueError:
            raise CommandError(
                f"--ident: {args.ident[:40]!r} is not a 16-bit number such as 0x0402",
                Exit.BAD_INPUT,
            ) from None
    cfg = _hex_bytes(args.cfg, "--cfg") if args.cfg is not None else None
    user_prm = _hex_bytes(args.user_prm, "--user-prm") if args.user_prm is not None else None
    given = DpGiven(args.ppo, ident, args.gsd, cfg, user_prm)
    found, problems = dp_settings.resolve(given, _option)
    if found is None:
        key, text = problems[0]
        where = f"{_option(key)}: " if key and key != "gsd" else ""
        raise CommandError(f"{where}{text}", Exit.BAD_INPUT)
    ident, user_prm, cfg, dpv1 = found.ident, found.user_prm, found.cfg, found.dpv1
    slot = _slot_time(args, found.gsd)
    watchdog = dp_settings.watchdog(slot, args.retries, 1)  # the one slave it addresses
    try:
        parameters = dps.Parameters(ident, dps.watchdog_factors(watchdog), user_prm=user_prm)
        parameters.encode()
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    access = getattr(args, "access", None) or ("pkw" if kind.has_pkw else "ds47")
    record = None
    if access == "ds47":
        axis = args.axis if args.axis is not None else AXES.get(dia.name)
        if axis is None:
            raise CommandError(
                f"--access ds47: the {dia.name} dialect documents the PKW channel only"
                " (give --axis to use data record 47 anyway)",
                Exit.BAD_INPUT,
            )
        dpv1 = dpv1 or Dpv1Setup()
        if not dpv1.read_write:
            raise CommandError(
                f"--access ds47: the GSD file says C1_Read_Write_supp = 0: the slave reads"
                f" and writes no data records ({args.gsd})",
                Exit.BAD_INPUT,
            )
        record = RecordAccess(axis, max_data=dpv1.max_data)
    elif not kind.has_pkw:
        raise CommandError(f"PPO {kind.number} has no PKW words: --access ds47", Exit.BAD_INPUT)
    elif getattr(args, "axis", None) is not None:
        raise CommandError("--axis applies to --access ds47 only", Exit.BAD_INPUT)
    return DpContext(
        dia, kind, parameters, cfg, args.master_address, args.retries, record,
        dpv1 if record is not None else None, slot,
    )  # fmt: skip


def _slot_time(args: argparse.Namespace, found: Gsd | None) -> float:
    """``--slot-time``, else the default at the rate, waiting for the slave's GSD MaxTsdr;
    bad input where the GSD file says the slave does not run at the rate, or may answer
    later than ``--slot-time``."""
    rate = args.baudrate or DEFAULT_BAUDRATE
    tsdr = found.max_tsdr.get(rate) if found is not None else None
    if found is not None and found.supports(rate) is False:
        raise CommandError(
            f"--gsd {args.gsd}: the slave does not run at {rate} baud (the file names"
            f" {found.rates_text()}): give --baudrate",
            Exit.BAD_INPUT,
        )
    if (
        args.slot_time is not None
        and tsdr is not None
        and args.slot_time < dp_timing.bits(tsdr, rate)
    ):
        raise CommandError(
            f"--slot-time: the slave may begin to answer {tsdr} bit times"
            f" ({dp_timing.bits(tsdr, rate) * 1000:.3g} ms) after a request at {rate} baud"
            f" (its GSD file's MaxTsdr): give a longer one",
            Exit.BAD_INPUT,
        )
    return dp_settings.slot_time(rate, args.slot_time, [found])


def fdl_port(
    args: argparse.Namespace, slot_time: float | None = None, *, clear_on_close: bool = False
) -> FdlPort:
    """The command's DP port (``clear_on_close``: of a master that parametrises slaves, which
    it clears before the port closes)."""
    try:
        settings = PortSettings(
            limits.check_port_url(args.port),
            baudrate=args.baudrate or DEFAULT_BAUDRATE,
            parity="E",
            echo=args.echo,
        )
        return FdlPort(
            settings,
            args.master_address,
            slot_time=slot_time if slot_time is not None else args.slot_time,
            trace=print_trace if args.trace else None,
            clear_on_close=clear_on_close,
        )
    except ValueError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None


async def session(
    args: argparse.Namespace,
    ctx: DpContext,
    address: int,
    jobs: Sequence[pkw.PkwRequest],
    vtype: ValueType | None = None,
) -> list[Outcome]:
    """Run ``jobs`` one after the other on slave ``address`` through the line runner (the
    master listens first, parametrises the slave, and clears it at the end)."""
    spec = DriveSpec("drive", carrier_for(ctx.target(address)))
    watch = _Watch(address)
    line = fdl_port(args, ctx.slot_time, clear_on_close=True)
    wire = CycleWire([SlaveSpec(spec, ctx.setup(address), ctx.ppo)], name="command line")
    drive = watch.session = LineSession(line, wire, [spec], retries=ctx.retries, observers=[watch])
    loop = asyncio.get_running_loop()
    outcomes: list[Outcome] = []
    try:
        await drive.open()
        for request in jobs:
            deadline = loop.time() + getattr(args, "deadline", DEFAULT_DEADLINE)
            outcomes.append((await drive.job(spec.name, request, deadline, vtype)).outcome)
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    except SessionEnded as exc:
        if exc.kind is EndKind.TIMEOUT:  # the slave does not answer: no valid answer
            outcomes.append(TimedOut(str(exc)))
        else:
            raise CommandError(str(exc), Exit.NO_ANSWER, kind=exc.kind) from None
    finally:
        await drive.close()
    refused = watch.refusal(ctx.parameters.ident)
    if refused is not None:  # never in data exchange: say why, not only that time ran out
        outcomes = [TimedOut(refused) if isinstance(o, TimedOut) else o for o in outcomes]
    return outcomes


class _Watch:
    """Ends a command's session early, from the line's stream of events: the slave owned by
    another master, the slave not answering at all, the line given up (another master
    heard on it)."""

    def __init__(self, address: int) -> None:
        self.address = address
        self.session: LineSession | None = None
        self.state = SlaveState.OFFLINE
        self.owner: int | None = None
        self.diagnosis: dps.Diagnosis | None = None  # the slave's last
        self.exchanged = False  # in data exchange at some time

    def refusal(self, ident: int) -> str | None:
        """Why the slave never came to data exchange, where its diagnosis says it refuses
        what it was sent (Prm_Fault, Cfg_Fault: PROFIBUS DP Slave_Diag, station status 1);
        ``ident`` the ident number it was parametrised with."""
        d = self.diagnosis
        if d is None or self.exchanged:
            return None
        return refusal(self.address, d.flags, d.ident, ident, OPTIONS)

    def _end(self, kind: EndKind, reason: str) -> None:
        if self.session is not None:
            self.session.end(kind, reason)

    def on_events(self, events: Sequence[Event]) -> None:
        for event in events:
            if isinstance(event, SlaveDiagnosed):
                self.owner = event.diagnosis.master
                self.diagnosis = event.diagnosis
            elif isinstance(event, SlaveStateChanged):
                self.state = event.state
                self.exchanged = self.exchanged or event.state is SlaveState.DATA_EXCHANGE
                if event.state is SlaveState.LOCKED:
                    self._end(EndKind.LOCKED, str(SlaveLocked(self.address, self.owner)))
            elif isinstance(event, SlaveSilent):
                self._end(EndKind.TIMEOUT, f"slave {self.address} does not answer ({event.detail})")
            elif isinstance(event, LineState) and not event.up and event.error:
                self._end(EndKind.LINE_ERROR, event.error)
