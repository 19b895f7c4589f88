"""Every duration a user gives has a range, from one table; outside it is a placed error."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from pkwbus.notation import durations
from pkwbus.notation.durations import DurationRange, parse_duration
from pkwbus.service.config import ConfigError, parse_config, parse_sim_port

README = Path(__file__).resolve().parents[3] / "README.md"

LINE = """\
lines:
  - name: l1
    port: {port}
    protocol: fc
    baudrate: 19200
{setting}
    drives:
      - name: d1
        address: 1
        poll: [{{parameter: "16-13", every: {every}}}]
"""


def config(setting: str = "", every: str = "1s", port: str = "/dev/ttyUSB0") -> str:
    return LINE.format(setting=f"    {setting}" if setting else "", every=every, port=port)


def problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, environ={})
    return caught.value.problems


# (the setting's place, how to write the value into a configuration, its range)
FIELDS = [
    ("lines[0].timeout", lambda v: config(f"timeout: {v}"), durations.TELEGRAM_TIMEOUT),
    ("lines[0].pause", lambda v: config(f"pause: {v}"), durations.PAUSE),
    (
        "lines[0].inter_char_timeout",
        lambda v: config(f"inter_char_timeout: {v}"),
        durations.INTER_CHAR_TIMEOUT,
    ),
    ("lines[0].response_delay", lambda v: config(f"response_delay: {v}"), durations.RESPONSE_DELAY),
    ("lines[0].drives[0].poll[0].every", lambda v: config(every=v), durations.POLL_INTERVAL),
]
ABSURD = ['"999999999999h"', "1e400", ".inf", "-.inf", ".nan", "-1", '"-5ms"', "25h"]


@pytest.mark.parametrize(("place", "write", "kind"), FIELDS, ids=[f[0] for f in FIELDS])
@pytest.mark.parametrize("value", ABSURD)
def test_an_absurd_duration_is_a_placed_error(
    place: str, write: object, kind: DurationRange, value: str
) -> None:
    assert callable(write)
    found = problems(write(value))
    assert len(found) == 1 and found[0].startswith(f"{place}: "), found


@pytest.mark.parametrize(("place", "write", "kind"), FIELDS, ids=[f[0] for f in FIELDS])
def test_the_ends_of_each_range(place: str, write: object, kind: DurationRange) -> None:
    assert callable(write)
    for inside in (kind.low, kind.high):
        if inside > 0:
            parse_config(write(repr(inside)), environ={})
    above = problems(write(repr(kind.high * 1.001)))
    assert above == [f"{place}: {kind.high * 1.001!r} is too long for {kind.what} ({kind})"]
    if kind.low > 0:
        below = problems(write(repr(kind.low * 0.999)))
        assert below == [f"{place}: {kind.low * 0.999!r} is too short for {kind.what} ({kind})"]
        assert problems(write("0")) == [
            f"{place}: 0 is not a duration above 0: {kind.what} is {kind}"
        ]
    else:
        parse_config(write("0"), environ={})


def test_a_simulated_ports_response_delay_has_the_same_range() -> None:
    assert parse_sim_port("sim://fc?drives=1&response_delay=10s").response_delay == 10.0
    with pytest.raises(ValueError, match=r"response_delay '11s' is too long.*0 to 10 s"):
        parse_sim_port("sim://fc?drives=1&response_delay=11s")
    found = problems(config(port="sim://fc?drives=1&response_delay=999999999999h"))
    assert found[0].startswith("lines[0].port: ") and "too long" in found[0], found


@pytest.mark.parametrize("kind", [kind for _, kind in durations.RANGES])
def test_every_range_refuses_what_is_not_finite_or_negative(kind: DurationRange) -> None:
    for value in (math.inf, -math.inf, math.nan, 10**400, -1, "-1s", "inf", "nan"):
        with pytest.raises(ValueError, match="duration"):
            parse_duration(value, kind)
    assert 0 <= kind.low < kind.high < math.inf


def test_the_readme_lists_the_table() -> None:
    text = README.read_text(encoding="utf-8")
    rows = re.findall(r"^\| (.+?) \| ((?:\d[\d.]* (?:ms|s|min|h)|0) to .+?) \|$", text, re.M)
    assert rows == [(where, str(kind)) for where, kind in durations.RANGES]
