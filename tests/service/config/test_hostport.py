"""HOST:PORT is parsed in one place: the service's listen, the simulator's
--listen/--stats-listen and a socket:// or rfc2217:// port say the same."""

from __future__ import annotations

import pytest

from pkwbus.notation.hostport import ANY_FREE_PORT, parse_host_port
from pkwbus.notation.limits import check_port_url
from pkwbus.service.config import parse_listen
from pkwbus.sim.cli import parse_host_port as parse_sim_listen


@pytest.mark.parametrize(
    ("text", "lowest", "scheme", "expected"),
    [
        ("127.0.0.1:9725", 1, "", ("127.0.0.1", 9725)),
        ("[::1]:65535", 1, "", ("::1", 65535)),
        ("gw_1.plant:4001", 1, "", ("gw_1.plant", 4001)),
        ("tcp://127.0.0.1:0", ANY_FREE_PORT, "tcp://", ("127.0.0.1", 0)),
        ("tcp://[::]:5020", ANY_FREE_PORT, "tcp://", ("::", 5020)),
    ],
)
def test_host_and_port(text: str, lowest: int, scheme: str, expected: tuple[str, int]) -> None:
    assert parse_host_port(text, lowest_port=lowest, scheme=scheme) == expected


def _problem(call: object, *args: str) -> str:
    with pytest.raises(ValueError) as caught:
        call(*args)  # type: ignore[operator]
    return str(caught.value)


@pytest.mark.parametrize(
    ("listen", "sim", "url"),
    [
        ("host:70000", "tcp://host:70000", "socket://host:70000"),
        ("::1:80", "tcp://::1:80", "socket://::1:80"),
        ("a b:1", "tcp://a b:1", "rfc2217://a b:1"),
        ("[zz]:1", "tcp://[zz]:1", "socket://[zz]:1"),
        ("host", "tcp://host", "socket://host"),
        ("host:x", "tcp://host:x", "rfc2217://host:x"),
    ],
)
def test_the_three_say_the_same(listen: str, sim: str, url: str) -> None:
    """Each mistake gets the same words whichever of the three it is written in."""
    said = [
        _problem(parse_listen, listen).replace(repr(listen), "TEXT"),
        _problem(parse_sim_listen, sim, "tcp://").replace(repr(sim), "TEXT"),
        _problem(check_port_url, url).replace(repr(url), "TEXT"),
    ]
    for variant in ("tcp://", "socket://", "rfc2217://", "0-65535 (0: any free port)", "1-65535"):
        said = [s.replace(variant, "") for s in said]
    assert said[0] == said[1] == said[2]


def test_port_ranges() -> None:
    """Port 0 is any free port for the simulator and the service's listen (its log names the
    port it got); a port URL, connected to, needs 1+."""
    assert parse_sim_listen("tcp://127.0.0.1:0", "tcp://") == ("127.0.0.1", 0)
    assert parse_listen("127.0.0.1:0") == ("127.0.0.1", 0)
    assert _problem(parse_listen, "127.0.0.1:65536").endswith(
        "the TCP port must be 0-65535 (0: any free port)"
    )
    assert _problem(check_port_url, "socket://127.0.0.1:0").endswith("the TCP port must be 1-65535")
    assert _problem(parse_sim_listen, "tcp://127.0.0.1:65536", "tcp://").endswith(
        "the TCP port must be 0-65535 (0: any free port)"
    )


def test_port_url_keeps_its_query_and_other_ports() -> None:
    assert check_port_url("rfc2217://gw:4001?logging=debug") == "rfc2217://gw:4001?logging=debug"
    assert check_port_url("/dev/ttyUSB0") == "/dev/ttyUSB0"
    assert check_port_url("loop://") == "loop://"
