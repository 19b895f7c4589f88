"""`pkwbus audit`: a table people read, with ISO times, units and outcomes; --json for scripts."""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import pytest

from pkwbus.cli import main
from pkwbus.commands.audit_table import stamp, table, units_from
from pkwbus.service.audit.log import AuditEntry, AuditLog
from pkwbus.service.config import load_config

NOW = 1_700_000_000.0  # 2023-11-14T22:13:20Z
PLUS_ONE = datetime.timezone(datetime.timedelta(hours=1))

CONFIG = """\
audit_db: {db}
lines:
  - name: l1
    port: socket://127.0.0.1:9
    protocol: fc
    baudrate: 9600
    drives:
      - {{name: fan1, address: 1, catalog: danfoss-fc, writable: ["3-41"]}}
      - {{name: raw, address: 2, writable: ["3-41"]}}
"""


def entries() -> list[AuditEntry]:
    return [
        AuditEntry(
            "10.0.0.7", "fan1", "3-41", 0, "ok", store="ram", old_value=5.0, new_value=12.5,
            time=NOW + 60,
        ),
        AuditEntry(
            "10.0.0.7", "fan1", "3-41", 0, "rejected", store="eeprom", old_value=12.5,
            new_value=70000, fault=3, detail="value out of range", time=NOW + 30,
        ),
        AuditEntry("10.0.0.8", "raw", "3-41", 2, "ok", old_value=None, new_value=7, time=NOW),
        AuditEntry("10.0.0.9", "", "", 0, "refused", count=4, detail="unauthenticated 4", time=NOW),
    ]  # fmt: skip


@pytest.fixture
def config_file(tmp_path: Path) -> Path:
    db = tmp_path / "audit.sqlite"
    log = AuditLog(db)
    for entry in reversed(entries()):
        log.clock = lambda t=entry.time: t
        log.record(entry)
    log.close()
    path = tmp_path / "pkwbus.yaml"
    path.write_text(CONFIG.format(db=db))
    return path


def test_time_is_iso_with_its_zone() -> None:
    assert stamp(NOW, PLUS_ONE) == "2023-11-14T23:13:20+01:00"
    assert stamp(NOW, datetime.UTC) == "2023-11-14T22:13:20+00:00"


def test_table_columns_units_and_outcomes(config_file: Path) -> None:
    unit_of = units_from(load_config(config_file))
    lines = table(entries(), unit_of, PLUS_ONE)
    assert lines[0].split() == [
        "TIME", "DRIVE", "PARAMETER", "CHANGE", "STORE", "OUTCOME", "CLIENT", "DETAIL",
    ]  # fmt: skip
    columns = [lines[0].index(h) for h in ("DRIVE", "PARAMETER", "CHANGE", "STORE", "OUTCOME")]
    for text in lines[1:]:  # aligned: every column starts under its heading
        assert all(text[c - 2 : c] == "  " and text[c] != " " for c in columns), text
    assert lines[1].split("  ")[0] == "2023-11-14T23:14:20+01:00"
    assert "5 s -> 12.5 s" in lines[1] and " ram " in lines[1] and " ok " in lines[1]
    assert "12.5 s -> 70000 s" in lines[2] and "rejected fault 3" in lines[2]
    assert lines[2].endswith("10.0.0.7  value out of range")
    assert (
        lines[3].split()[1:3] == ["raw", "3-41[2]"] and "? -> 7 " in lines[3]
    )  # no catalog: no unit
    assert "4 request(s)" in lines[4] and "refused" in lines[4] and "unauthenticated 4" in lines[4]


def test_audit_command_prints_the_table(
    config_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["audit", "--config", str(config_file)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("TIME ")
    assert len(out) == 1 + len(entries())
    assert "5 s -> 12.5 s" in out[1]
    when = datetime.datetime.fromisoformat(out[1].split()[0])
    assert when.tzinfo is not None and when.timestamp() == NOW + 60


def test_audit_json_for_scripts(config_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["audit", "--config", str(config_file), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [(r["drive"], r["outcome"], r["unit"]) for r in rows] == [
        ("fan1", "ok", "s"),
        ("fan1", "rejected", "s"),
        ("raw", "ok", None),
        ("", "refused", None),
    ]
    assert rows[0]["old_value"] == 5.0 and rows[0]["new_value"] == 12.5
    assert rows[0]["time"] == NOW + 60
