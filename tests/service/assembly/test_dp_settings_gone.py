"""A PROFIBUS slave's GSD file gone between the configuration's check and the line's start
(hot standby wins a line later, a reload): the line's start says what is wrong with it."""

from __future__ import annotations

from pathlib import Path

import pytest

from pkwbus.service.assembly.build import build_runtime
from pkwbus.service.config import parse_config
from tests.commands.test_dp_cli import GSD_TEXT


async def test_a_gsd_file_gone_since_the_check_is_named_when_the_line_starts(
    tmp_path: Path,
) -> None:
    gsd = tmp_path / "slave.gsd"
    gsd.write_text(GSD_TEXT)
    text = f"""
audit_db: {tmp_path}/audit.sqlite
lines:
  - name: dp
    port: /dev/pkwbus-test-no-port
    protocol: profibus
    baudrate: 93750
    drives:
      - {{name: s8, address: 8, dialect: danfoss-pcv, ppo: 1, gsd: {gsd}, catalog: danfoss-fc}}
"""
    config = parse_config(text, environ={})
    gsd.unlink()
    with pytest.raises(Exception) as exc:
        await build_runtime(config)
    assert "drive s8" in str(exc.value) and "slave.gsd" in str(exc.value), str(exc.value)
