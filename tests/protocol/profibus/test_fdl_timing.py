"""PROFIBUS DP bus timing (pkwbus.protocol.profibus.fdl.timing), against the figures of
EN 50170 vol. 2 part 4 ("timers") and of docs/profibus.md.

Up to 187.5 kbit/s: TSYN 33 bit times, min TSDR 11, max TSDR 60, slot time 100,
TID1 37; a character is 11 bits (start, 8 data, even parity, stop).
"""

from __future__ import annotations

import pytest

from pkwbus.protocol.profibus.fdl import timing


def test_the_standard_bit_times() -> None:
    assert timing.CHAR_BITS == 11
    assert (timing.TSYN_BITS, timing.MIN_TSDR_BITS, timing.MAX_TSDR_BITS) == (33, 11, 60)
    assert (timing.TSL_BITS, timing.TID1_BITS, timing.TTO_SLOTS) == (100, 37, 6)


@pytest.mark.parametrize(
    ("baudrate", "seconds", "shown"),
    # docs/profibus.md: 5.2 ms at 19.2 kbit/s, 1.07 ms at 93.75 kbit/s (rounded as shown)
    [(19200, 0.0052, 0.0001), (93750, 0.00107, 0.00001)],
)
def test_the_stock_slot_time_of_100_bits(baudrate: int, seconds: float, shown: float) -> None:
    assert timing.bits(timing.TSL_BITS, baudrate) == pytest.approx(seconds, abs=shown / 2)


@pytest.mark.parametrize("baudrate", [0, -93750])
def test_a_baud_rate_that_is_not_positive_is_refused(baudrate: int) -> None:
    with pytest.raises(ValueError, match=f"baud rate {baudrate} is not positive"):
        timing.bits(1, baudrate)
    with pytest.raises(ValueError, match="not positive"):
        timing.wire_time(6, baudrate)


def test_a_character_is_11_bit_times_on_the_wire() -> None:
    # The FDL status request of the captured Festo start-up, 10 08 02 49 53 16:
    # 6 characters.
    assert timing.wire_time(6, 9600) == pytest.approx(66 / 9600)
    assert timing.wire_time(0, 9600) == 0


@pytest.mark.parametrize(
    ("baudrate", "seconds"),
    [
        (9600, 0.030),  # docs/profibus.md: 30 ms at 19200 and below
        (19200, 0.030),
        (45450, 0.015),  # between
        (93750, 0.008),  # 8 ms at 93750 and above
        (187500, 0.008),
    ],
)
def test_the_default_slot_time_over_a_usb_adapter(baudrate: int, seconds: float) -> None:
    assert timing.default_slot_time(baudrate) == pytest.approx(seconds)


def test_the_slot_time_is_never_below_100_bit_times() -> None:
    # At 1200 baud 100 bit times (83 ms) are longer than any USB adapter's delay.
    assert timing.default_slot_time(1200) == pytest.approx(100 / 1200)


def test_a_gsd_max_tsdr_beyond_60_bit_times_lengthens_the_slot_time() -> None:
    # A slave whose GSD says MaxTsdr_93.75 = 160 answers up to 100 bit times later
    # than the standard's 60.
    assert timing.default_slot_time(93750, 160) == pytest.approx(0.008 + 100 / 93750)
    # one at or within the standard's 60 adds nothing
    assert timing.default_slot_time(93750, 60) == timing.default_slot_time(93750)
    assert timing.default_slot_time(93750, 15) == timing.default_slot_time(93750)
    assert timing.default_slot_time(93750, None) == pytest.approx(0.008)


def test_the_token_lost_time_is_6_plus_2_x_address_slot_times() -> None:
    # docs/profibus.md: pkwbus listens 6 + 2 x its station address slot times.
    assert timing.token_lost_time(0.008, 2) == pytest.approx(10 * 0.008)
    assert timing.token_lost_time(0.030, 0) == pytest.approx(6 * 0.030)
    assert timing.token_lost_time(0.001, 125) == pytest.approx(256 * 0.001)


def test_one_exchange_at_best() -> None:
    # The captured Festo FDL status request (6 characters) and its answer
    # 10 02 08 00 0A 16 (6 characters): 12 characters of 11 bits, then TSYN 33
    # before the request, min TSDR 11 before the answer and TID1 37 after it.
    expected = (12 * 11 + 33 + 11 + 37) / 93750
    assert timing.exchange_time(6, 6, 93750) == pytest.approx(expected)
    assert timing.exchange_time(0, 0, 9600) == pytest.approx(81 / 9600)
