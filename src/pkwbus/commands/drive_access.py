"""One drive on the command line, on any bus: what `read`, `write` and `describe` share.

:func:`drive_access` gives the drive's dialect, its catalog, how a request is
checked before anything is sent, and how requests run on it one after the
other, in one opening of the port, by the one line runner
(:class:`pkwbus.master.sessions.session.LineSession`): on FC and USS over the
line's exchange wire, over PROFIBUS DP over the cycle wire, through the
slave's start-up and its PKW slot (:func:`pkwbus.commands.profibus.context.session`). The
commands themselves are the same for every bus.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for bad
input or a port that cannot be opened.
"""

from __future__ import annotations

import argparse
import asyncio
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import Any

from pkwbus.catalog.description import ParameterDescription
from pkwbus.commands.answers import catalog_entry, drive_name
from pkwbus.commands.common import (
    DEFAULT_CATALOG,
    PROFIBUS,
    CommandError,
    Exit,
    build_port,
    build_target,
)
from pkwbus.commands.profibus.context import DEFAULT_DEADLINE, DP_CATALOGS, build_context, session
from pkwbus.link import PortError
from pkwbus.master.carriers import carrier_for
from pkwbus.master.planning.carrier import Carrier, Item
from pkwbus.master.planning.outcomes import Outcome
from pkwbus.master.planning.plan import DriveSpec
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.wires.serial.wire import ExchangeWire
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.values import ParameterRef, parse_parameter, parse_type
from pkwbus.protocol.values.types import ValueType

__all__ = ["DriveAccess", "checked", "drive_access", "resolve"]

# The jobs, one after the other, and the value type they are known by (None: not known).
Run = Callable[[Sequence[pkw.PkwRequest], ValueType | None], Coroutine[Any, Any, list[Outcome]]]


@dataclass(frozen=True)
class DriveAccess:
    """The drive the command line names, on its bus."""

    dialect: Dialect
    catalog: str  # the catalog its parameters are decoded with by default ('none': none)
    texts: bool  # whether a text parameter travels (not in the 4 PKW words of a PPO)
    check: Callable[[pkw.PkwRequest], object]  # LocalProtocolError: it cannot be sent
    run: Run
    # Whether its answers name each value's type (PROFIdrive data record 47's formats).
    typed_answers: bool = False


def drive_access(args: argparse.Namespace) -> DriveAccess:
    if args.protocol == PROFIBUS:
        ctx = build_context(args)
        slave = carrier_for(ctx.target(args.address))  # its PKW slot, or data record 47

        def check_ppo(request: pkw.PkwRequest) -> object:
            return slave.preview(Item(request))

        def run_dp(
            requests: Sequence[pkw.PkwRequest], vtype: ValueType | None
        ) -> Coroutine[Any, Any, list[Outcome]]:
            return session(args, ctx, args.address, requests, vtype)

        catalog = DP_CATALOGS.get(ctx.dialect.name) or "none"
        typed = ctx.record is not None
        return DriveAccess(ctx.dialect, catalog, False, check_ppo, run_dp, typed)
    try:
        target = build_target(args)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None

    carrier = carrier_for(target)

    def check_line(request: pkw.PkwRequest) -> object:
        return carrier.preview(Item(request))

    def run_line(
        requests: Sequence[pkw.PkwRequest], vtype: ValueType | None
    ) -> Coroutine[Any, Any, list[Outcome]]:
        return _jobs(args, carrier, requests)

    catalog = DEFAULT_CATALOG[Bus(args.protocol)]
    return DriveAccess(target.dialect, catalog, True, check_line, run_line)


async def _jobs(
    args: argparse.Namespace, carrier: Carrier, requests: Sequence[pkw.PkwRequest]
) -> list[Outcome]:
    """``requests`` one after the other through the line runner, over the line's wire."""
    spec = DriveSpec("drive", carrier)
    port = build_port(args)
    session = LineSession(port, ExchangeWire(port.timeout), [spec], retries=args.retries)
    try:
        await session.open()
    except PortError as exc:
        raise CommandError(str(exc), Exit.PORT) from None
    loop = asyncio.get_running_loop()
    outcomes: list[Outcome] = []
    try:
        for request in requests:
            deadline = loop.time() + getattr(args, "deadline", DEFAULT_DEADLINE)
            outcomes.append((await session.job(spec.name, request, deadline)).outcome)
    finally:
        await session.close()
    return outcomes


def resolve(
    args: argparse.Namespace, access: DriveAccess, *, typed: bool = True
) -> tuple[ParameterRef, ParameterDescription]:
    """The parameter named on the command line, in the drive's notation, and its format
    (with ``typed``: the catalog's, ``--catalog`` or the bus's, and ``--type``)."""
    try:
        ref = parse_parameter(args.parameter)
        access.dialect.check_pnu(ref.pnu)
        vtype = parse_type(args.type) if typed and args.type else None
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    known = ParameterDescription()
    if typed:
        known = catalog_entry(getattr(args, "catalog", None) or access.catalog, ref.pnu)
    try:
        ref = drive_name(ref, access.dialect, known)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    fmt = known.with_type(vtype)
    if fmt.is_text and not access.texts:
        raise CommandError("a text parameter does not fit the 4 PKW words of a PPO", Exit.BAD_INPUT)
    return ref, fmt


def checked(access: DriveAccess, requests: Sequence[pkw.PkwRequest]) -> list[pkw.PkwRequest]:
    """``requests``, each one the drive can be sent; else bad input, nothing sent."""
    try:
        for request in requests:
            access.check(request)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    return list(requests)
