"""The `pkwbus` command. No traceback reaches the user unless --debug asks for one."""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from pkwbus import __version__
from pkwbus.commands import access, describe, gsd, ports, scan, service
from pkwbus.commands.common import CommandError, Exit
from pkwbus.commands.settings import backup, restore
from pkwbus.sim import cli as sim_cli

__all__ = ["Parser", "build_parser", "main"]


class Parser(argparse.ArgumentParser):
    """argparse with its usage errors in one line, saying where the help is; exit 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="pkwbus",
        description="Bus master for the PKW parameter channel of variable-frequency drives:"
        " Danfoss FC protocol and Siemens USS on RS-485, and PROFIBUS DP (DP-V0, DP-V1)",
    )
    parser.add_argument("--version", action="version", version=f"pkwbus {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logs")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    access.add_parsers(sub)
    scan.add_parsers(sub)
    describe.add_parsers(sub)
    backup.add_parsers(sub)
    restore.add_parsers(sub)
    service.add_parsers(sub)
    ports.add_parsers(sub)
    gsd.add_parsers(sub)
    sim_cli.add_parser(sub).set_defaults(func=sim_cli.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: usage errors exit 2, --help exits 0
        return int(exc.code or 0)
    logging.basicConfig(
        level=logging.DEBUG if args.debug else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.func(args))
    except CommandError as exc:
        _report(args, exc)
        return int(exc.code)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return Exit.INTERRUPTED
    except BrokenPipeError:  # the reader of its output went away (| head): said by the shell
        with contextlib.suppress(OSError):  # what is still buffered goes nowhere at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return Exit.PIPE_CLOSED
    except Exception as exc:
        if args.debug:
            raise
        print(
            f"pkwbus: internal error: {type(exc).__name__}: {exc} (--debug shows more)",
            file=sys.stderr,
        )
        return Exit.BUG


def _report(args: argparse.Namespace, exc: CommandError) -> None:
    print(str(exc) if exc.code is Exit.REJECTED else f"pkwbus: {exc}", file=sys.stderr)
    if getattr(args, "json", False):
        error: dict[str, object] = {"kind": exc.kind, "text": str(exc)}
        if exc.code is Exit.REJECTED:
            text = str(exc).partition(": ")[2] if exc.fault is not None else str(exc)
            error.update(fault=exc.fault, text=text)
        print(json.dumps({"error": error}))
