"""`pkwbus run`, `pkwbus check-config` and `pkwbus audit`: their command lines.

``pkwbus run`` loads the configuration and hands it to the service's composition
root (:mod:`pkwbus.service.assembly.root`).

Raises :class:`~pkwbus.commands.common.CommandError` with the exit code for a
configuration or audit log that cannot be used.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from pkwbus.commands.common import CommandError, Exit, int_option
from pkwbus.notation.limits import MAX_AUDIT_LIMIT
from pkwbus.service.config import Config, ConfigError, load_config
from pkwbus.service.config.line_load import check_config_report, poll_rates
from pkwbus.service.config.mqtt import mqtt_report

__all__ = ["add_parsers", "load", "run_audit", "run_check", "run_service"]


def add_parsers(sub: Any) -> None:
    run = sub.add_parser("run", help="run the bus master service")
    run.add_argument("--config", required=True, help="YAML configuration file")
    run.add_argument("--listen", default=None, help="HOST:PORT for HTTP (overrides the config)")
    run.add_argument("--log-format", choices=["text", "json"], default=None)
    run.set_defaults(func=run_service)
    check = sub.add_parser("check-config", help="validate a configuration, estimate line load")
    check.add_argument("file")
    check.add_argument(
        "--probe",
        action="store_true",
        help="also open each line briefly and ask each drive once (exit 3 if one does not answer)",
    )
    check.set_defaults(func=run_check)
    audit = sub.add_parser("audit", help="show the latest write attempts")
    audit.add_argument("--config", required=True)
    audit.add_argument(
        "--limit",
        type=int_option(1, MAX_AUDIT_LIMIT),
        default=50,
        help=f"how many of the latest attempts, 1-{MAX_AUDIT_LIMIT} (default 50)",
    )
    audit.add_argument("--json", action="store_true")
    audit.set_defaults(func=run_audit)


def load(path: str, listen: str | None = None) -> Config:
    try:
        config = load_config(path)
        return config.with_listen(listen) if listen else config
    except ConfigError as exc:
        raise CommandError(
            "invalid configuration:\n  " + "\n  ".join(exc.problems), Exit.BAD_INPUT
        ) from None


def run_check(args: argparse.Namespace) -> int:
    from pkwbus.service.audit.log import path_problem

    config = load(args.file)
    # The places the service opens before anything else, checked as `run` checks them.
    problems = [
        f"{key}: {problem}"
        for key, problem in (
            ("audit_db", path_problem(config.audit_db)),
            ("history_db", path_problem(config.history_path, "the history database")),
        )
        if problem is not None
    ]
    if problems:
        raise CommandError("invalid configuration:\n  " + "\n  ".join(problems), Exit.BAD_INPUT)
    for line in check_config_report(config):
        print(line)
    if config.mqtt is not None:
        rates = [r for line, drive in config.drives() for r in poll_rates(line, drive)]
        for line in mqtt_report(config.mqtt, rates, sum(1 for _ in config.drives())):
            print(line)
    if args.probe:
        from pkwbus.commands.probe import run_probe

        return run_probe(config)
    return Exit.OK


def run_service(args: argparse.Namespace) -> int:
    from pkwbus.service.assembly import root

    config = load(args.config, args.listen)

    def reread() -> Config:  # a reload reads the file as the start did (ConfigError)
        fresh = load_config(args.config)
        return fresh.with_listen(args.listen) if args.listen else fresh

    try:
        root.run_service(
            config, log_format=args.log_format or config.log_format, debug=args.debug,
            reread=reread,
        )  # fmt: skip
    except root.StartError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    return Exit.OK


def run_audit(args: argparse.Namespace) -> int:
    from pkwbus.commands.audit_table import table, units_from
    from pkwbus.service.audit.log import AuditError, AuditLog, as_dict

    config = load(args.config)
    if not config.audit_db.exists():
        raise CommandError(f"no audit database at {config.audit_db}", Exit.BAD_INPUT)
    if not config.audit_db.is_file():
        raise CommandError(f"{config.audit_db} is not an audit database file", Exit.BAD_INPUT)
    try:  # read-only: creates nothing, not even the key file
        audit = AuditLog(config.audit_db, readonly=True)
        try:
            entries = audit.latest(args.limit)
        finally:
            audit.close()
    except AuditError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    unit_of = units_from(config)
    if args.json:
        rows = [as_dict(e) | {"unit": unit_of(e.drive, e.parameter) or None} for e in entries]
        print(json.dumps(rows))
        return Exit.OK
    if not entries:
        print("no write attempts recorded", file=sys.stderr)
        return Exit.OK
    for text in table(entries, unit_of):
        print(text)
    return Exit.OK
