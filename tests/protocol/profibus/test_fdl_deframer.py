"""The streaming FDL deframer (pkwbus.protocol.profibus.fdl.deframer): what it says of
bytes that are no frame, and its reset."""

from __future__ import annotations

import pytest

from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.fdl import BadLength, Deframer, ShortAck, Skipped

# The captured Festo FDL status request (pyprofibus issue 19).
FDL_STATUS = bytes.fromhex("10 08 02 49 53 16")


def test_bytes_before_a_frame_are_named_as_skipped() -> None:
    assert Skipped(3).describe() == "3 bytes skipped"
    with pytest.raises(RemoteProtocolError, match="not one FDL frame: 2 bytes skipped"):
        fdl.decode(b"\x00\x00" + FDL_STATUS)


def test_an_sd2_length_outside_4_249_is_refused_before_the_rest_arrives() -> None:
    # LE 02: no SD2 frame is that short, so the deframer need not wait for LEr.
    deframer = Deframer()
    assert deframer.feed(b"\x68\x02") == [BadLength(b"\x68\x02"), Skipped(1)]
    assert deframer.buffered == 0
    # LE FA (250): beyond MAX_LE 249
    assert Deframer().feed(b"\x68\xfa\xfa")[0] == BadLength(b"\x68\xfa")


def test_an_sd2_length_in_range_waits_for_the_rest() -> None:
    deframer = Deframer()
    assert deframer.feed(b"\x68\x05") == []
    assert deframer.buffered == 2


def test_reset_forgets_a_partial_frame_and_the_hunt() -> None:
    deframer = Deframer()
    assert deframer.feed(b"\x00" + FDL_STATUS[:3]) == [Skipped(1)]  # hunting, 3 bytes kept
    assert deframer.buffered == 3
    deframer.reset()
    assert deframer.buffered == 0
    # in step again, as at the start: a short acknowledge is taken at once
    assert deframer.feed(b"\xe5") == [ShortAck()]
