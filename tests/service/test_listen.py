"""The HTTP address: a port in use is told with the ways to choose another."""

from __future__ import annotations

import socket

import pytest

from pkwbus.service.app import ListenError, bind


def test_an_address_in_use_names_the_options_that_change_it() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(ListenError) as info:
            bind("127.0.0.1", port).close()
    message = str(info.value)
    assert f"127.0.0.1:{port}" in message
    assert "--listen" in message and "PKWBUS_LISTEN" in message


def test_a_free_address_is_bound_and_listening() -> None:
    sock = bind("127.0.0.1", 0)
    try:
        with socket.create_connection(sock.getsockname()[:2], timeout=5):
            pass
    finally:
        sock.close()
