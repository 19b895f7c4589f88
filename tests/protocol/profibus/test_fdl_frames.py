"""FDL frame fields that exist only in one direction, and what is no frame at all
(pkwbus.protocol.profibus.fdl.frames; EN 50170 vol. 2 part 4, "telegram formats")."""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import LocalProtocolError, RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.fdl import FrameControl, Function, StationType, Status


def test_a_request_has_a_function_and_no_status_or_station_type() -> None:
    # FC 6D: the captured Festo Slave_Diag request (SRD high, FCB set).
    request = FrameControl(0x6D)
    assert request.function is Function.SRD_HIGH
    assert request.status is None
    assert request.station_type is None


def test_a_response_has_a_status_and_station_type_and_no_function() -> None:
    # FC 08: the captured Festo diagnosis answer (DL, from a slave).
    response = FrameControl(0x08)
    assert response.status is Status.DL
    assert response.station_type is StationType.SLAVE
    assert response.function is None


def test_the_base_frame_is_no_frame_to_send() -> None:
    with pytest.raises(LocalProtocolError, match="Frame is not an FDL frame"):
        fdl.encode(fdl.Frame())


@pytest.mark.parametrize("body", [b"", b"\x08", b"\x08\x02"])
def test_a_body_without_da_sa_and_fc_is_the_peers_error(body: bytes) -> None:
    with pytest.raises(RemoteProtocolError, match=f"frame body of {len(body)} bytes"):
        fdl.decode_body(body)


def test_the_smallest_body_is_an_sd1_frame() -> None:
    # 10 08 02 49 53 16, the captured FDL status request: DA 08, SA 02, FC 49.
    assert fdl.decode_body(bytes.fromhex("08 02 49")) == fdl.DataFrame(8, 2, 0x49)
