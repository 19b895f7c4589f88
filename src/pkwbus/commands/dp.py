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
from pathlib import Path

from pkwbus import durations, limits
from pkwbus.commands.common import CommandError, Exit, duration_option, int_option, print_trace
from pkwbus.link import LinkState, PortError, PortSettings
from pkwbus.master.cycle_wire import CycleWire, NoDpEvents, SlaveSpec
from pkwbus.master.dp_line import DpLine
from pkwbus.master.dp_master import SlaveLocked, SlaveRun
from pkwbus.master.outcomes import Outcome, TimedOut
from pkwbus.master.plan import DriveSpec
from pkwbus.master.record import NoEvents
from pkwbus.master.single_job import JobSession, SessionEnded
from pkwbus.master.target import DriveTarget, RecordAccess
from pkwbus.master.transaction import ErrorKind, ExchangeResult, Failure
from pkwbus.protocol import dp_services as dps
from pkwbus.protocol import dp_timing, gsd, pkw, ppo
from pkwbus.protocol.dialects import Dialect
from pkwbus.protocol.dp_slave import SlaveSetup, SlaveState
from pkwbus.protocol.dpv1 import Dpv1Setup
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.ppo import PkwSlot, PpoType
from pkwbus.protocol.profidrive import AXES
from pkwbus.protocol.telegram import BlockShape, Protocol
from pkwbus.protocol.value_types import ValueType

__all__ = [
    "DEFAULT_BAUDRATE",
    "DEFAULT_DEADLINE",
    "DP_CATALOGS",
    "MAX_DP_RETRIES",
    "DpContext",
    "add_dp_options",
    "build_context",
    "dp_line",
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
                Protocol.PROFIBUS, address, self.dialect, ppo.LAYOUT, shape, record=self.record
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


def _from_gsd(path: str, number: int) -> tuple[int, bytes, bytes, Dpv1Setup | None]:
    """Ident, user parameters, the PPO's module identifiers and (a DP-V1 slave) its class 1
    services from a GSD file."""
    try:
        text = Path(path).read_text(encoding="latin-1")
    except OSError as exc:
        raise CommandError(f"--gsd: cannot read {path}: {exc.strerror}", Exit.BAD_INPUT) from None
    try:
        found = gsd.parse(text)
    except gsd.GsdError as exc:
        raise CommandError(f"--gsd {path}: {exc}", Exit.BAD_INPUT) from None
    wanted = ppo.ppo_type(number)
    modules = [m for m in found.modules if m.cfg.lstrip(b"\x00") == wanted.cfg]
    if not modules:
        modules = [m for m in found.modules if f"ppo{number}" in m.name.casefold().replace(" ", "")]
    if not modules:
        known = ", ".join(repr(m.name) for m in found.modules) or "none"
        raise CommandError(
            f"--gsd {path}: no module for PPO {number} (modules: {known}); give --cfg",
            Exit.BAD_INPUT,
        )
    module = modules[0]
    return found.ident, found.prm_for([module]), module.cfg, found.dpv1


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
    cfg, user_prm, dpv1 = kind.cfg, b"", None
    if args.gsd is not None:
        ident, user_prm, cfg, dpv1 = _from_gsd(args.gsd, args.ppo)
    elif args.ident is not None:
        try:
            ident = limits.check_int(int(args.ident, 0), 0, 0xFFFF)
        except ValueError:
            raise CommandError(
                f"--ident: {args.ident[:40]!r} is not a 16-bit number such as 0x0402",
                Exit.BAD_INPUT,
            ) from None
    else:
        raise CommandError(
            "give the slave's ident number (--ident 0x0402) or its GSD file (--gsd FILE)",
            Exit.BAD_INPUT,
        )
    if args.cfg is not None:
        cfg = _hex_bytes(args.cfg, "--cfg")
    if args.user_prm is not None:
        user_prm = _hex_bytes(args.user_prm, "--user-prm")
    slot = args.slot_time or dp_timing.default_slot_time(args.baudrate or DEFAULT_BAUDRATE)
    # The watchdog: several worst-case cycles, at least a second.
    watchdog = max(1.0, 10 * slot * (args.retries + 1))
    try:
        parameters = dps.Parameters(ident, dps.watchdog_factors(watchdog), user_prm=user_prm)
        parameters.encode()
        dps.check_cfg(cfg)
        inputs, outputs = dps.io_lengths(cfg)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    if (inputs, outputs) != (kind.length, kind.length):
        raise CommandError(
            f"the configuration {cfg.hex(' ')} sets up {inputs}/{outputs} bytes in/out;"
            f" PPO {kind.number} has {kind.length}",
            Exit.BAD_INPUT,
        )
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
        dpv1 if record is not None else None,
    )  # fmt: skip


def dp_line(args: argparse.Namespace) -> DpLine:
    try:
        settings = PortSettings(
            limits.check_port_url(args.port),
            baudrate=args.baudrate or DEFAULT_BAUDRATE,
            parity="E",
            echo=args.echo,
        )
        return DpLine(
            settings,
            args.master_address,
            slot_time=args.slot_time,
            trace=print_trace if args.trace else None,
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
    spec = DriveSpec("drive", ctx.target(address))
    watch = _Watch(address)
    wire = CycleWire(dp_line(args), [SlaveSpec(spec, ctx.setup(address), ctx.ppo)], dp_events=watch)
    drive = watch.session = JobSession(wire, spec, retries=ctx.retries, events=watch)
    watch.wire = wire
    wire.link.reconnect.add_listener(watch.port)
    loop = asyncio.get_running_loop()
    outcomes: list[Outcome] = []
    try:
        await drive.open()
        for request in jobs:
            deadline = loop.time() + getattr(args, "deadline", DEFAULT_DEADLINE)
            outcomes.append((await drive.job(request, deadline, vtype)).outcome)
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    except SessionEnded as exc:
        if exc.kind == "timeout":  # the slave does not answer: no valid answer
            outcomes.append(TimedOut(str(exc)))
        else:
            raise CommandError(str(exc), Exit.NO_ANSWER, kind=exc.kind) from None
    finally:
        await drive.close()
    return outcomes


class _Watch(NoEvents, NoDpEvents):
    """Ends a command's session early: the slave owned by another master, the slave not
    answering at all, another master heard on the line."""

    def __init__(self, address: int) -> None:
        self.address = address
        self.session: JobSession | None = None
        self.wire: CycleWire | None = None

    def _run(self) -> SlaveRun | None:
        return self.wire.master.runs.get(self.address) if self.wire is not None else None

    def _end(self, kind: str, reason: str) -> None:
        if self.session is not None:
            self.session.end(kind, reason)

    def slave_state(self, drive: str, state: SlaveState) -> None:
        run = self._run()
        if state is SlaveState.LOCKED and run is not None:
            diagnosis = run.slave.diagnosis
            owner = diagnosis.master if diagnosis is not None else None
            self._end("locked", str(SlaveLocked(self.address, owner)))

    def exchange(self, drive: str, result: ExchangeResult, busy: float) -> None:
        run = self._run()
        if not isinstance(result, Failure) or result.kind is not ErrorKind.TIMEOUT or run is None:
            return
        if run.slave.state is SlaveState.OFFLINE and not run.slave.waiting:
            self._end("timeout", f"slave {self.address} does not answer ({result.detail})")

    def port(self, state: LinkState, error: str | None) -> None:
        if state is LinkState.FAILED and error:
            self._end("line_error", error)
