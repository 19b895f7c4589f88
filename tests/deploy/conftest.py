"""Helpers for the deployment tests: a service config for a simulator."""

from __future__ import annotations

from pathlib import Path

# Drives of the test line: name -> bus address.
DRIVES = {"fan_a": 1, "fan_b": 2}
# Values set in the simulator (raw, conversion index -2 in the catalog) -> seconds.
RAMP_RAW = {"fan_a": 1234, "fan_b": 567}
RAMP_SECONDS = {"fan_a": 12.34, "fan_b": 5.67}


# The PROFIBUS DP slave of the optional DP line: name -> station address.
DP_DRIVES = {"mixer": 8}


def dp_line_config(port: str) -> str:
    """A PROFIBUS DP line on ``port`` with one Danfoss slave (PPO 1) polling 16-13."""
    drives = "".join(
        f"""
      - name: {name}
        address: {address}
        dialect: danfoss-pcv
        ident: 0x0402
        catalog: danfoss-fc
        poll:
          - {{parameter: "16-13", every: 250ms}}
"""
        for name, address in DP_DRIVES.items()
    )
    return f"""
  - name: dp_line_config
    port: {port}
    protocol: profibus
    baudrate: 19200
    drives:{drives}"""


def service_config(
    port: str, folder: Path, extra_poll: str = "", dp_port: str | None = None
) -> str:
    """A `pkwbus run` config: one FC line on ``port``, both drives polling 3-41 and 16-13;
    with ``dp_port`` also a PROFIBUS DP line (:func:`dp_line_config`)."""
    drives = "".join(
        f"""
      - name: {name}
        address: {address}
        catalog: danfoss-fc
        poll:
          - {{parameter: "3-41", every: 250ms}}
          - {{parameter: "16-13", every: 250ms}}{extra_poll}
"""
        for name, address in DRIVES.items()
    )
    return f"""\
listen: 127.0.0.1:9725
audit_db: {folder / "audit.sqlite"}
lines:
  - name: test_line
    port: {port}
    protocol: fc
    baudrate: 19200
    parity: E
    timeout: 200ms
    retries: 2
    drives:{drives}""" + (dp_line_config(dp_port) if dp_port is not None else "")
