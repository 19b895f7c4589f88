"""`pkwbus read`, `write` and `describe` over PROFIBUS DP: the same output and exit codes
as over FC and USS, the job carried by the slave's PPO.

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code, as over FC and
USS.
"""

from __future__ import annotations

import argparse
from typing import Any

from pkwbus import link
from pkwbus.commands.answers import finish, report_value, show_read
from pkwbus.commands.common import CommandError, Exit
from pkwbus.commands.descriptions import ELEMENTS, report
from pkwbus.commands.dp import DpContext, build_context, resolve, session
from pkwbus.commands.failures import command_failure
from pkwbus.master.outcomes import Answered, Outcome, Rejected
from pkwbus.protocol import pkw, ppo
from pkwbus.protocol.dialects import Command
from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError

__all__ = ["run_describe", "run_read", "run_write"]


def _outcomes(args: argparse.Namespace, coro: Any) -> list[Outcome]:
    found: list[Outcome] = link.run(coro)
    return found


def run_read(args: argparse.Namespace) -> int:
    ctx = build_context(args)
    ref, fmt = resolve(args, ctx)
    try:
        req = pkw.read_parameter(ctx.dialect, ref.pnu, ref.index, text=False)
        ppo_check(ctx, req)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    (outcome,) = _outcomes(args, session(args, ctx, args.address, [req]))
    return show_read(args, ref, fmt, outcome)


def run_write(args: argparse.Namespace) -> int:
    ctx = build_context(args)
    ref, fmt = resolve(args, ctx)
    store = pkw.Store(args.store)
    try:
        raw, width = fmt.encode(args.value, str(ref))
        req = pkw.write(ctx.dialect, ref.pnu, raw, width, index=ref.index, store=store)
        ppo_check(ctx, req)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    (outcome,) = _outcomes(args, session(args, ctx, args.address, [req]))
    response = finish(outcome)
    try:
        got, value = fmt.value_of(response)
    except RemoteProtocolError:
        got, value = raw, args.value
    report_value(args, ref, got, value, fmt, f" written ({store.value})")
    return Exit.OK


def ppo_check(ctx: DpContext, req: pkw.PkwRequest) -> None:
    """The request fits a PPO-write (LocalProtocolError when not): nothing is sent otherwise."""
    ppo.encode_ppo_write(ctx.ppo, ctx.dialect, req)


def run_describe(args: argparse.Namespace) -> int:
    ctx = build_context(args)
    if not ctx.dialect.has(Command.READ_DESCRIPTION):
        raise CommandError(
            f"the {ctx.dialect.name} dialect has no description request (AK 4)", Exit.BAD_INPUT
        )
    ref, _ = resolve(args, ctx, typed=False)
    try:
        jobs = [pkw.read_description(ctx.dialect, ref.pnu, e) for e in ELEMENTS]
        for req in jobs:
            ppo_check(ctx, req)
    except LocalProtocolError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    outcomes = _outcomes(args, session(args, ctx, args.address, jobs))
    found: dict[int, pkw.DescriptionResponse | None] = {}
    for element, outcome in zip(ELEMENTS, outcomes, strict=True):
        if isinstance(outcome, Answered) and isinstance(outcome.response, pkw.DescriptionResponse):
            found[element] = outcome.response
        elif isinstance(outcome, Answered | Rejected):
            found[element] = None
        else:
            failure = command_failure(outcome)
            assert failure is not None
            raise CommandError(failure.message, failure.code)
    return report(args, ref, found)
