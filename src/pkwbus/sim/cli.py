"""``pkwbus simulate``: simulated drives on a TCP port or a pseudo-terminal."""

from __future__ import annotations

import argparse
import asyncio
import random
import signal
import sys
from dataclasses import dataclass
from typing import Any

from pkwbus.catalog import DEFAULT_CATALOGS, CatalogError
from pkwbus.notation import durations, hostport, limits
from pkwbus.notation.durations import DurationRange
from pkwbus.protocol import buses
from pkwbus.protocol.errors import ProtocolError
from pkwbus.protocol.pkw.dialects import DIALECTS, IndLayout
from pkwbus.sim.config import LAG_MODES, SimFaults, SimTiming
from pkwbus.sim.drives.model import TRIPS_PER_HOUR, WARNINGS_PER_HOUR, ModelConfig
from pkwbus.sim.profibus.line import DpFaults, DpSimulator
from pkwbus.sim.serving.ends import PathInUseError, PtyEnd, TcpEnd, drop_at_random
from pkwbus.sim.serving.statsout import StatsServer, keep_stats_file
from pkwbus.sim.simulator import Simulator

__all__ = [
    "EXIT_PORT",
    "EXIT_USAGE",
    "FAULT_OPTIONS",
    "Plan",
    "add_parser",
    "catalog_for",
    "configure",
    "main",
    "parse_addresses",
    "parse_host_port",
    "plan",
    "run",
    "serve",
]

EXIT_USAGE = 2
EXIT_PORT = 4
FAULT_OPTIONS = ("drop", "corrupt", "truncate", "garbage", "wrong_address", "late", "stale")


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``simulate`` to the ``pkwbus`` command's subparsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "simulate", help="simulated drives on a TCP port or a pty", description=__doc__
    )
    configure(parser)
    return parser


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--protocol", choices=("fc", "uss", "profibus"), default="fc")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--listen", metavar="tcp://HOST:PORT", help="serve raw telegrams on TCP")
    where.add_argument(
        "--pty",
        metavar="PATH",
        help="create a pty, symlinked at PATH; refused (exit 2) while a simulator serves PATH,"
        " a stale link of a dead one is replaced",
    )
    parser.add_argument("--drives", default="1", help="addresses: 1,2,5 or 1-3 (default 1)")
    parser.add_argument("--dialect", choices=sorted(DIALECTS))
    parser.add_argument("--ind-layout", choices=[x.value for x in IndLayout])
    parser.add_argument(
        "--pkw-words",
        default="variable",
        help="USS: 0, 3, 4 or variable (127, the default: Siemens drives' factory setting)",
    )
    parser.add_argument("--pzd-words", type=int, default=2, help="USS: 0-16 (default 2)")
    parser.add_argument(
        "--catalog",
        help="serve parameters with this catalog's types, scaling and units (default: the"
        " protocol's default catalog, the one pkwbus read decodes with: danfoss-fc for fc,"
        " siemens-g120 for uss); 'none' for the built-in table alone",
    )
    parser.add_argument("--seed", type=int)
    dp = parser.add_argument_group("PROFIBUS DP (--protocol profibus)")
    dp.add_argument("--ppo", type=int, choices=range(1, 6), default=1, help="PPO type (default 1)")
    dp.add_argument(
        "--ident", help="the slaves' ident number, e.g. 0x0402 (default: the dialect's)"
    )
    dp.add_argument("--dpv1", action="store_true", help="DP-V1 slaves (data record 47)")
    dp.add_argument("--not-ready", type=int, default=0, metavar="N",
                    help="DP-V1: reads of each record answered 'state conflict' first")  # fmt: skip
    timing = parser.add_argument_group("timing")
    timing.add_argument("--response-delay", default="3ms", help="e.g. 3ms (default), 0.01, 1s")
    timing.add_argument("--baudrate", type=int)
    timing.add_argument("--wire-timing", action="store_true", help="spend 11 bits a character")
    timing.add_argument("--lag", default="0", help="PKW lag: N telegrams or a duration (50ms)")
    timing.add_argument("--lag-mode", choices=LAG_MODES, default="none")
    faults = parser.add_argument_group("faults (probability per answer)")
    for name in FAULT_OPTIONS:
        faults.add_argument(f"--{name.replace('_', '-')}", type=float, default=0.0, metavar="P")
    faults.add_argument("--rs", type=float, default=0.0, metavar="P", help="profibus: answer RS")
    faults.add_argument(
        "--restart", type=float, default=0.0, metavar="P", help="profibus: the slave restarts"
    )
    faults.add_argument(
        "--warnings-per-hour",
        type=float,
        default=WARNINGS_PER_HOUR,
        metavar="N",
        help="how often a drive raises a warning (default %(default)g; 0: never)",
    )
    faults.add_argument(
        "--trips-per-hour",
        type=float,
        default=TRIPS_PER_HOUR,
        metavar="N",
        help="how often a drive trips (default %(default)g; 0: never)",
    )
    faults.add_argument(
        "--drop-port-per-hour",
        type=float,
        default=0.0,
        metavar="N",
        help="how often the port is lost at random: TCP connections cut, the pty removed"
        " and made again at the same path (default 0: never; at most 3600)",
    )
    faults.add_argument(
        "--port-outage", default="1s", help="how long a lost port stays lost (default 1s)"
    )
    faults.add_argument("--late-after", default="1s", help="how late a late answer is")
    faults.add_argument("--dead", default="", help="addresses that never answer: 3,4")
    faults.add_argument(
        "--refuse-descriptions",
        default="",
        metavar="ADDRESSES",
        help="drives that answer every description request (AK 4) with the dialect's"
        " 'description not available' fault: 3,5",
    )
    stats = parser.add_argument_group("stats")
    stats.add_argument("--stats-file", metavar="PATH", help="rewrite counters as JSON here")
    stats.add_argument("--stats-interval", default="1s")
    stats.add_argument("--stats-listen", metavar="HOST:PORT", help="serve GET /stats")


def parse_addresses(text: str) -> list[int]:
    """``1,2,5`` or ``1-3,7``; each address at most the highest of any protocol (126)."""
    return limits.parse_addresses(text, 0, limits.MAX_ADDRESS)


def parse_host_port(text: str, scheme: str = "") -> tuple[str, int]:
    """``--listen`` (``tcp://HOST:PORT``) or ``--stats-listen`` (``HOST:PORT``); port 0:
    any free port. ValueError otherwise (:func:`pkwbus.notation.hostport.parse_host_port`)."""
    return hostport.parse_host_port(text, lowest_port=hostport.ANY_FREE_PORT, scheme=scheme)


def catalog_for(protocol: str, name: str | None) -> str | None:
    """The catalog to serve with: the one named, else the protocol's default; None for 'none'."""
    name = name or DEFAULT_CATALOGS[protocol]
    return None if name == "none" else name


def _duration(option: str, text: str, within: DurationRange) -> float:
    try:
        return durations.parse_duration(text, within)
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def _lag(text: str) -> tuple[int, float]:
    """``--lag``: N telegrams, or a duration."""
    lag = text.strip()
    if not lag.isdigit():
        return 0, _duration("--lag", lag, durations.SIM_LAG)
    try:
        return limits.parse_int(lag, 0, limits.MAX_LAG_TELEGRAMS), 0.0
    except ValueError as exc:
        raise ValueError(f"--lag: {exc} (telegrams) or a duration") from None


def _pkw_words(text: str) -> int | None:
    try:
        return buses.pkw_words(text, text=True)
    except ValueError as exc:
        raise ValueError(f"--pkw-words: {exc}") from None


def _baudrate(value: int | None) -> int | None:
    if value is None:
        return None
    try:
        return limits.check_baudrate(value)
    except ValueError as exc:
        raise ValueError(f"--baudrate: {exc}") from None


@dataclass(frozen=True)
class Plan:
    sim: Simulator | DpSimulator
    listen: tuple[str, int] | None
    pty: str | None
    stats_file: str | None
    stats_interval: float
    stats_listen: tuple[str, int] | None
    drop_port_per_hour: float = 0.0
    port_outage: float = 1.0
    seed: int | None = None


def plan(args: argparse.Namespace) -> Plan:
    """Everything the options say, checked before anything opens. ValueError on bad input."""
    lag_telegrams, lag_seconds = _lag(args.lag)
    timing = SimTiming(
        response_delay=_duration("--response-delay", args.response_delay, durations.RESPONSE_DELAY),
        baudrate=_baudrate(args.baudrate),
        wire_timing=args.wire_timing,
        lag_telegrams=lag_telegrams,
        lag_seconds=lag_seconds,
        lag_mode=args.lag_mode,
    )
    probabilities = {name: getattr(args, name) for name in FAULT_OPTIONS}
    dead = frozenset(parse_addresses(args.dead))
    late = _duration("--late-after", args.late_after, durations.SIM_LATE)
    faults = SimFaults(**probabilities, late_seconds=late, dead=dead)
    model = _model(args)
    refusing = _refusing(args.refuse_descriptions, args.drives)
    if args.protocol == "profibus":
        return _plan(args, _dp_simulator(args, timing, faults, model, refusing))
    pkw_words = _pkw_words(args.pkw_words)
    sim = Simulator(
        args.protocol,
        parse_addresses(args.drives),
        dialect=args.dialect,
        ind_layout=IndLayout(args.ind_layout) if args.ind_layout else None,
        pkw_words=pkw_words,
        pzd_words=args.pzd_words,
        timing=timing,
        faults=faults,
        seed=args.seed,
        catalog=catalog_for(args.protocol, args.catalog),
        model=model,
        refuse_descriptions=refusing,
    )
    return _plan(args, sim)


def _refusing(text: str, drives: str) -> frozenset[int]:
    """``--refuse-descriptions``: addresses among ``--drives``."""
    try:
        refusing = frozenset(parse_addresses(text))
    except ValueError as exc:
        raise ValueError(f"--refuse-descriptions: {exc}") from None
    try:
        simulated = set(parse_addresses(drives))
    except ValueError:
        return refusing  # --drives says what is wrong with it
    strangers = sorted(refusing - simulated)
    if strangers:
        names = ",".join(str(a) for a in strangers)
        raise ValueError(f"--refuse-descriptions: {names} is not among --drives {drives[:40]}")
    return refusing


def _model(args: argparse.Namespace) -> ModelConfig:
    for option in ("warnings_per_hour", "trips_per_hour"):
        value = getattr(args, option)
        if not 0 <= value <= 3600:  # also refuses NaN
            raise ValueError(f"--{option.replace('_', '-')}: {value:g} is not 0-3600")
    return ModelConfig(
        warning_rate=args.warnings_per_hour / 3600, trip_rate=args.trips_per_hour / 3600
    )


def _dp_simulator(
    args: argparse.Namespace,
    timing: SimTiming,
    faults: SimFaults,
    model: ModelConfig,
    refusing: frozenset[int],
) -> DpSimulator:
    unused = [name for name in ("truncate", "wrong_address") if getattr(args, name)]
    if unused:
        raise ValueError(f"--{unused[0].replace('_', '-')} is not a PROFIBUS fault")
    try:
        ident = None if args.ident is None else int(args.ident, 0)
    except ValueError:
        raise ValueError(f"--ident: {args.ident[:20]!r} is not a number such as 0x0402") from None
    if ident is not None and not 0 <= ident <= 0xFFFF:
        raise ValueError(f"--ident: {ident:#x} is not 0x0000-0xFFFF")
    dp_faults = DpFaults(
        drop=faults.drop, corrupt=faults.corrupt, garbage=faults.garbage, late=faults.late,
        stale=faults.stale, rs=args.rs, restart=args.restart, late_seconds=faults.late_seconds,
        dead=faults.dead,
    )  # fmt: skip
    catalog = (
        "default" if args.catalog is None else None if args.catalog == "none" else args.catalog
    )
    return DpSimulator(
        parse_addresses(args.drives), dialect=args.dialect or "profidrive", ppo_number=args.ppo,
        ident=ident, timing=timing, faults=dp_faults, seed=args.seed, catalog=catalog,
        model=model, refuse_descriptions=refusing, dpv1=args.dpv1, not_ready=args.not_ready,
    )  # fmt: skip


def _plan(args: argparse.Namespace, sim: Simulator | DpSimulator) -> Plan:
    if not sim.drives:
        raise ValueError("--drives names no drive")
    if not 0 <= args.drop_port_per_hour <= 3600:  # also refuses NaN
        raise ValueError(f"--drop-port-per-hour: {args.drop_port_per_hour:g} is not 0-3600")
    return Plan(
        sim,
        parse_host_port(args.listen, "tcp://") if args.listen else None,
        args.pty,
        args.stats_file,
        _duration("--stats-interval", args.stats_interval, durations.STATS_INTERVAL),
        parse_host_port(args.stats_listen) if args.stats_listen else None,
        args.drop_port_per_hour,
        _duration("--port-outage", args.port_outage, durations.SIM_PORT_OUTAGE),
        args.seed,
    )


def run(args: argparse.Namespace) -> int:
    try:
        the_plan = plan(args)
    except (ValueError, ProtocolError, CatalogError) as exc:
        print(f"pkwbus simulate: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        return asyncio.run(serve(the_plan))
    except PathInUseError as exc:
        print(f"pkwbus simulate: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"pkwbus simulate: cannot open: {exc}", file=sys.stderr)
        return EXIT_PORT
    except KeyboardInterrupt:
        return 0


async def serve(p: Plan) -> int:
    """Open the ends, say where, run until SIGINT or SIGTERM, close cleanly."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    sim = p.sim
    drives = ",".join(str(a) for a in sim.drives)
    closers = []
    end: TcpEnd | PtyEnd
    if p.listen is not None:
        end = await sim.serve_tcp(*p.listen)
        where = end.url
    else:
        assert p.pty is not None
        end = await sim.serve_pty(p.pty)
        where = f"{end.path} -> {end.device}"
    closers.append(end.close)
    tasks = []
    if p.stats_listen is not None:
        server = StatsServer(sim.stats)
        await server.start(*p.stats_listen)
        closers.append(server.close)
        print(f"stats on http://{p.stats_listen[0]}:{server.port}/stats", flush=True)
    if p.stats_file is not None:
        tasks.append(
            asyncio.create_task(keep_stats_file(sim.stats, p.stats_file, p.stats_interval))
        )
    if isinstance(sim, DpSimulator):
        what = f"profibus slaves {drives} ({sim.dialect.name}, PPO {sim.ppo.number}, ident"
        what += f" {sim.ident:#06x})"
    else:
        what = f"{sim.protocol.value} drives {drives} ({sim.dialect.name})"
    print(f"simulating {what} on {where}", flush=True)
    watched: list[asyncio.Task[Any]] = [asyncio.create_task(stop.wait())]
    if p.drop_port_per_hour > 0:
        rng = random.Random(p.seed)
        drops = drop_at_random(end, p.drop_port_per_hour, p.port_outage, rng, _say)
        watched.append(asyncio.create_task(drops))
    try:
        await asyncio.wait(watched, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in [*tasks, *watched]:
            task.cancel()
        ended = await asyncio.gather(*tasks, *watched, return_exceptions=True)
        for close in reversed(closers):
            await close()
    # A port that could not be made again after a loss ends the simulator (exit 2 or 4).
    for outcome in ended:
        if isinstance(outcome, Exception):  # not CancelledError, a BaseException
            raise outcome
    return 0


def _say(text: str) -> None:
    print(text, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pkwbus.sim", description=__doc__)
    configure(parser)
    return run(parser.parse_args(argv))
