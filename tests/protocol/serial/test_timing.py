"""Character and telegram timing on an RS-485 line (pkwbus.protocol.serial.timing).

A character is a start bit, 8 data bits, a parity bit unless the parity is N and
1 or 2 stop bits: 11 bits for the 8E1 Danfoss and Siemens default to (Danfoss FC
100 Design Manual, port parameters; SINAMICS S110 function manual, USS).
"""

from __future__ import annotations

import pytest

from pkwbus.protocol.serial import timing


@pytest.mark.parametrize(
    ("parity", "stopbits", "bits"),
    [("E", 1, 11), ("O", 1, 11), ("N", 1, 10), ("N", 2, 11), ("E", 2, 12)],
)
def test_bits_per_character(parity: str, stopbits: int, bits: int) -> None:
    assert timing.char_bits(parity, stopbits) == bits


def test_the_default_character_is_8e1() -> None:
    assert timing.char_bits() == timing.DEFAULT_CHAR_BITS == 11


@pytest.mark.parametrize(
    ("parity", "stopbits", "why"),
    [("M", 1, "parity 'M' is not E, O or N"), ("e", 1, "parity 'e'"), ("E", 3, "stop bits 3")],
)
def test_a_character_format_the_line_cannot_have_is_refused(
    parity: str, stopbits: int, why: str
) -> None:
    with pytest.raises(ValueError, match=why):
        timing.char_bits(parity, stopbits)


def test_a_character_at_9600_baud_8e1_takes_11_bit_times() -> None:
    assert timing.char_time(9600) == pytest.approx(11 / 9600)
    assert timing.char_time(19200, "N", 1) == pytest.approx(10 / 19200)


@pytest.mark.parametrize("baudrate", [0, -9600])
def test_a_baud_rate_that_is_not_positive_is_refused(baudrate: int) -> None:
    with pytest.raises(ValueError, match=f"baud rate {baudrate} is not positive"):
        timing.char_time(baudrate)


def test_a_telegram_takes_one_character_time_a_byte() -> None:
    character = timing.char_time(9600)
    # An FC telegram with 4 PKW words and 2 PCD words is 16 bytes long
    # (STX, LGE, ADR, 12 data bytes, BCC): 16 x 11 bit times.
    assert timing.wire_time(16, character) == pytest.approx(16 * 11 / 9600)
    assert timing.wire_time(0, character) == 0


def test_the_start_pause_is_three_and_a_half_characters_unless_given() -> None:
    # USS asks for at least 2 character times of quiet before a request;
    # pkwbus waits 3.5.
    character = timing.char_time(9600)
    assert timing.start_pause(character) == pytest.approx(3.5 * 11 / 9600)
    assert timing.start_pause(character) >= 2 * character
    assert timing.start_pause(character, 0.02) == 0.02
    assert timing.start_pause(character, 0.0) == 0.0  # given: even none


def test_the_gap_that_ends_a_telegram_is_20_characters_at_least_5_ms() -> None:
    slow = timing.char_time(9600)
    assert timing.inter_char_gap(slow) == pytest.approx(20 * 11 / 9600)  # 22.9 ms
    fast = timing.char_time(115200)
    assert 20 * fast < 0.005
    assert timing.inter_char_gap(fast) == timing.MIN_INTER_CHAR_GAP == 0.005
    assert timing.inter_char_gap(slow, 0.1) == 0.1  # a timeout given wins
    # wider than the start pause: a telegram never ends inside the pause before the next
    assert timing.inter_char_gap(slow) > timing.start_pause(slow)
