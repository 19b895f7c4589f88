"""`pkwbus gsd FILE`: what pkwbus reads from a GSD file, to see it before configuring.

The file is read as ``--gsd FILE`` and a configuration's ``gsd:`` read it
(:func:`pkwbus.catalog.dp_settings.read_gsd_file`): the vendor, model and ident
number, DP-V1, the baud rates the slave supports with ``MaxTsdr`` at each,
the default user parameter bytes, the modules in file order with their
configuration identifiers and, for a drive, which module is which PPO; and
the lines read past. Exit 2 with the line and the reason where the file is
not a GSD file pkwbus can use.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from pkwbus.catalog.dp_settings import GsdFileError, read_gsd_file
from pkwbus.commands.common import CommandError, Exit
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus import gsd
from pkwbus.protocol.profibus.dp import services as dp_services
from pkwbus.protocol.profibus.gsd import Gsd, GsdModule

__all__ = ["add_parsers", "gsd_report", "run_gsd"]

_STATIONS = {0: "DP slave", 1: "DP master"}


def add_parsers(sub: Any) -> None:
    parser = sub.add_parser(
        "gsd", help="show what pkwbus reads from a PROFIBUS GSD file (.gsd .gse .gsg ...)"
    )
    parser.add_argument("file", help="the GSD file, as its vendor ships it")
    parser.add_argument("--json", action="store_true", help="machine-readable output")
    parser.set_defaults(func=run_gsd)


def run_gsd(args: argparse.Namespace) -> int:
    try:
        found = read_gsd_file(args.file)
    except GsdFileError as exc:
        raise CommandError(str(exc), Exit.BAD_INPUT, kind="gsd") from None
    report = gsd_report(args.file, found)
    if args.json:
        print(json.dumps(report, indent=1, ensure_ascii=False))
    else:
        print(_text(report))
    return Exit.OK


def gsd_report(path: str, found: Gsd) -> dict[str, Any]:
    """What the file says, as ``--json`` prints it."""
    family = found.family
    dpv1 = found.dpv1
    rates = sorted(found.baud_rates | found.max_tsdr.keys())
    return {
        "file": path,
        "gsd_revision": found.revision,
        "vendor": found.vendor,
        "model": found.model,
        "revision": found.texts.get("revision", ""),
        "order_number": found.texts.get("ordernumber", ""),
        "ident": f"0x{found.ident:04X}",
        "station_type": _STATIONS.get(found.station_type, str(found.station_type)),
        "family": None
        if family is None
        else {"main": family.main, "name": family.name, "sub": list(family.sub)},
        "dpv1": None
        if dpv1 is None
        else {
            "read_write": dpv1.read_write,
            "max_data": dpv1.max_data,
            "response_timeout": dpv1.response_timeout,
        },
        "baud_rates": [
            {
                "baudrate": rate,
                "supported": rate in found.baud_rates,
                "max_tsdr": found.max_tsdr.get(rate),
            }
            for rate in rates
        ],
        "user_prm": found.user_prm.hex(" ").upper(),
        "modules": [_module(i, m) for i, m in enumerate(found.modules, 1)],
        "warnings": list(found.warnings),
    }


def _module(place: int, module: GsdModule) -> dict[str, Any]:
    try:
        inputs, outputs = dp_services.io_lengths(module.cfg)
        io: dict[str, int] | None = {"inputs": inputs, "outputs": outputs}
    except RemoteProtocolError:
        io = None  # identifiers pkwbus cannot size: shown as they are
    return {
        "place": place,
        "name": module.name,
        "cfg": module.cfg.hex(" ").upper(),
        "reference": module.reference,
        "user_prm": module.user_prm.hex(" ").upper(),
        "bytes": io,
        "ppo": gsd.ppo_of(module),
    }


def _text(report: dict[str, Any]) -> str:
    lines = [
        f"file:        {report['file']}",
        f"vendor:      {report['vendor']}",
        f"model:       {report['model']}"
        + (f" (revision {report['revision']})" if report["revision"] else ""),
        f"ident:       {report['ident']}  {report['station_type']}"
        + (f", GSD revision {report['gsd_revision']}" if report["gsd_revision"] else ""),
    ]
    if report["order_number"]:
        lines.append(f"order no.:   {report['order_number']}")
    family = report["family"]
    if family is not None:
        subs = "".join(f" / {s}" for s in family["sub"])
        lines.append(f"family:      {family['main']} {family['name']}{subs}")
    dpv1 = report["dpv1"]
    if dpv1 is None:
        lines.append("DP-V1:       no (a DP-V0 slave)")
    else:
        lines.append(
            "DP-V1:       yes, data records "
            + ("read and written" if dpv1["read_write"] else "not read or written (class 1)")
            + f", at most {dpv1['max_data']} bytes, response within"
            f" {dpv1['response_timeout'] * 1000:g} ms"
        )
    lines.append("baud rates:  rate        MaxTsdr (bit times)")
    for rate in report["baud_rates"]:
        tsdr = rate["max_tsdr"] if rate["max_tsdr"] is not None else "-"
        note = "" if rate["supported"] else "  (not supported)"
        lines.append(f"             {rate['baudrate']:<10}  {tsdr}{note}")
    lines.append(f"user_prm:    {report['user_prm'] or '(none)'}")
    lines.append(f"modules:     {len(report['modules'])}")
    for m in report["modules"]:
        ref = f"#{m['reference']}" if m["reference"] is not None else ""
        size = f"{m['bytes']['inputs']}/{m['bytes']['outputs']} bytes" if m["bytes"] else ""
        ppo = f"PPO {m['ppo']}" if m["ppo"] else ""
        lines.append(
            f"  {m['place']:>3} {ref:<6} {m['name']!r:<40} {m['cfg']:<15} {size:<14} {ppo}"
        )
        if m["user_prm"]:
            lines.append(f"             its user_prm: {m['user_prm']}")
    for warning in report["warnings"]:
        lines.append(f"read past:   {warning}")
    return "\n".join(line.rstrip() for line in lines)
