"""A command whose output's reader goes away (``| head``, ``| true``): exit 141, as the shell
says of a command killed by SIGPIPE, and no traceback, no "internal error"."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

CONFIG = """\
audit_db: {folder}/audit.sqlite
lines:
  - name: l
    port: sim://fc?drives=1
    protocol: fc
    baudrate: 19200
    drives:
      - {{name: fan, address: 1, catalog: danfoss-fc}}
"""


def test_check_config_into_a_closed_pipe_exits_141_quietly(tmp_path: Path) -> None:
    path = tmp_path / "pkwbus.yaml"
    path.write_text(CONFIG.format(folder=tmp_path))
    proc = subprocess.Popen(
        [sys.executable, "-m", "pkwbus", "check-config", str(path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader is gone before a line is written
    err = proc.stderr.read().decode()
    assert proc.wait(60) == 141, err
    assert "Traceback" not in err and "internal error" not in err
