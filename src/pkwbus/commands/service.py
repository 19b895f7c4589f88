"""`pkwbus run`, `pkwbus check-config` and `pkwbus audit`."""

from __future__ import annotations

import argparse
import datetime
import json
import logging
import sys
from typing import Any

from pkwbus import link
from pkwbus.commands.common import CommandError, Exit, int_option
from pkwbus.limits import MAX_AUDIT_LIMIT
from pkwbus.service.config import Config, ConfigError, load_config
from pkwbus.service.load import check_config_report

log = logging.getLogger("pkwbus")


def add_parsers(sub: Any) -> None:
    run = sub.add_parser("run", help="run the bus master service")
    run.add_argument("--config", required=True, help="YAML configuration file")
    run.add_argument("--listen", default=None, help="HOST:PORT for HTTP (overrides the config)")
    run.add_argument("--log-format", choices=["text", "json"], default=None)
    run.set_defaults(func=run_service)
    check = sub.add_parser("check-config", help="validate a configuration, estimate line load")
    check.add_argument("file")
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
    config = load(args.file)
    for line in check_config_report(config):
        print(line)
    return Exit.OK


def run_service(args: argparse.Namespace) -> int:
    from pkwbus.service.app import ListenError, bind
    from pkwbus.service.logs import setup_logging

    config = load(args.config, args.listen)
    setup_logging(args.log_format or config.log_format, debug=args.debug)
    try:
        sock = bind(config.listen.host, config.listen.port)
    except ListenError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT) from None
    link.run(_serve(config, sock))
    return Exit.OK


async def _serve(config: Config, sock: Any) -> None:
    from pkwbus.service.api import create_app
    from pkwbus.service.app import serve
    from pkwbus.service.audit import AuditLog
    from pkwbus.service.build import build_runtime

    runtime = await build_runtime(config)
    audit = AuditLog(config.audit_db)
    interrupted = audit.close_interrupted()
    if interrupted:
        log.warning("audit log: %d write(s) were in flight when the service last died", interrupted)
    token = config.write_token()
    app = create_app(runtime, audit=audit, write_token=token)
    host = config.listen.host
    shown = f"[{host}]" if ":" in host else host
    log.info("pkwbus: metrics on http://%s:%d/metrics", shown, config.listen.port)
    log.info("writes %s", "allowed with the token" if token else "refused: no write token is set")
    try:
        await serve(runtime, app, sock)
    finally:
        audit.close()


def run_audit(args: argparse.Namespace) -> int:
    from pkwbus.service.audit import AuditLog, as_dict

    if args.limit < 1:
        raise CommandError("--limit must be at least 1", Exit.BAD_INPUT)
    config = load(args.config)
    if not config.audit_db.exists():
        raise CommandError(f"no audit database at {config.audit_db}", Exit.BAD_INPUT)
    audit = AuditLog(config.audit_db, readonly=True)
    try:
        entries = audit.latest(args.limit)
    finally:
        audit.close()
    if args.json:
        print(json.dumps([as_dict(e) for e in entries]))
        return Exit.OK
    for e in entries:
        stamp = datetime.datetime.fromtimestamp(e.time).strftime("%Y-%m-%d %H:%M:%S")
        where = f"{e.drive} {e.parameter}" + (f"[{e.index}]" if e.index else "")
        change = f"{e.old_value!r} -> {e.new_value!r}"
        fault = f" fault {e.fault}" if e.fault is not None else ""
        print(f"{stamp} {e.client} {where} {change} {e.outcome}{fault} {e.detail or ''}".rstrip())
    if not entries:
        print("no write attempts recorded", file=sys.stderr)
    return Exit.OK
