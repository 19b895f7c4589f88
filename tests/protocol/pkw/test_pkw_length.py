"""Where a USS PKW length puts a value, checked against the Siemens and NORD documents,
and what a drive's answers tell of its length.

Sources:
- SIMOVERT MASTERDRIVES Compendium Motion Control (6SE7087-6QX70), 8.1, "PKW area":
  a 16-bit value with 4 fixed words in PWE2 (4th word), PWE1 = 0; with a variable
  length in PWE1, "there is no PWE2"; a 32-bit value in PWE1 (high) and PWE2 (low).
- SINAMICS G120X Operating Instructions, 6.3 "USS parameter channel": p2023 = 4
  "always contains four words ... The values are right-justified in the 4th word".
- MICROMASTER 420 Reference Manual, 3.3.5: with P2013 = 127 the request
  243A 0000 4220 0000 is answered 743A 0000 0005, a reply of 3 words.
- NORD BU 0050, 1.6.4: a word change in 4 fixed words, 02 0E 03 20 66 00 01 00 00
  03 E8 00 00 00 00 (its printed BCC, 80, is wrong: the XOR of the bytes is A3).
"""

from __future__ import annotations

import pytest

from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import Command, IndLayout, dialect
from pkwbus.protocol.pkw.length import AUTO, VARIABLE, Gate, PkwLength, shown, told
from pkwbus.protocol.serial.telegram import BlockShape, bcc, frame

USS = dialect("uss")
LAYOUT = IndLayout.USS
FAULT_5 = USS.fault(5)


def words(hexes: str) -> bytes:
    return bytes.fromhex(hexes.replace(" ", ""))


def word_change(pnu: int, value: int, subindex: int = 0) -> pkw.PkwRequest:
    """AK 2, change a word, as the documents' examples write it (also with an index)."""
    return pkw.request(USS, Command.WRITE_WORD, pnu, subindex=subindex, value=value)


@pytest.mark.parametrize(
    ("pkw_words", "expected"),
    [
        (4, "22BC 0000 0000 0005"),  # PWE1 = 0, the value right-justified in the 4th word
        (VARIABLE, "22BC 0000 0005"),  # PWE1 carries it, no PWE2
        (3, "22BC 0000 0005"),
    ],
)
def test_a_word_change_is_placed_as_the_length_says(pkw_words: int | None, expected: str) -> None:
    # P0700 = 5 (MASTERDRIVES Compendium, 8.1: where a 16-bit value goes)
    assert pkw.encode_request(word_change(700, 5), USS, LAYOUT, pkw_words) == words(expected)


@pytest.mark.parametrize("pkw_words", [4, VARIABLE])
def test_a_double_word_travels_alike_with_4_words_and_variable(pkw_words: int | None) -> None:
    # P1082 = 50.0: IEEE 754 0x42480000, high word in PWE1, low word in PWE2
    req = pkw.write(USS, 1082, 0x42480000, pkw.Width.DWORD)
    assert pkw.encode_request(req, USS, LAYOUT, pkw_words) == words("343A 0000 4248 0000")


def test_a_variable_read_carries_one_pwe_word() -> None:
    assert pkw.encode_request(pkw.read(USS, 1082), USS, LAYOUT, VARIABLE) == words("143A 0000 0000")


def test_the_nord_word_change_in_four_fixed_words() -> None:
    printed = words("02 0E 03 20 66 00 01 00 00 03 E8 00 00 00 00")
    target = DriveTarget.create("uss", 3, pkw_words=4)
    assert target.ind_layout is LAYOUT
    ours = SerialCarrier(target).telegram(word_change(102, 1000, subindex=1))
    assert ours[3:11] == printed[3:11]  # PKE 2066, IND 0001, PWE1 0000, PWE2 03E8
    assert bcc(printed) == 0xA3  # recomputed: the printed 80 is a misprint
    assert ours[:11] == printed[:11] and ours[-1] == bcc(ours[:-1])


def test_a_variable_follower_takes_a_word_from_pwe1() -> None:
    """What a factory-set drive does with a word change sent as 4 words (the defect): it
    takes PWE1, 0. With 4 fixed words it takes PWE2."""
    four = words("2460 0000 0000 04D2")  # p1120 = 1234 as a word, right-justified
    assert pkw.decode_request(four, USS, LAYOUT, VARIABLE).value == 0
    assert pkw.decode_request(four, USS, LAYOUT, 4).value == 0x04D2
    three = words("2460 0000 04D2")
    assert pkw.decode_request(three, USS, LAYOUT, VARIABLE).value == 0x04D2
    # MICROMASTER 420 Reference Manual, 3.3.5: the 4-word request as a follower reads it
    mm420 = pkw.decode_request(words("243A 0000 4220 0000"), USS, LAYOUT, VARIABLE)
    assert (mm420.command, mm420.pnu, mm420.value) == (Command.WRITE_WORD, 1082, 0x4220)


def test_the_mm420_three_word_reply_is_a_rejection_and_tells_a_variable_length() -> None:
    reply = words("743A 0000 0005")
    resp = pkw.decode_response(reply, USS, LAYOUT)
    assert isinstance(resp, pkw.Rejection) and (resp.pnu, resp.fault) == (1082, 5)
    assert told(4, len(reply) // 2, resp) is VARIABLE


@pytest.mark.parametrize(
    ("resp", "pkw_words", "expected"),
    [
        (pkw.ValueResponse(1, 52, 0, 0x0EB7, pkw.Width.WORD), VARIABLE, "1034 0000 0EB7"),
        (pkw.ValueResponse(1, 52, 0, 0x0EB7, pkw.Width.WORD), 4, "1034 0000 0000 0EB7"),
        (
            pkw.ValueResponse(2, 1082, 0, 0x42480000, pkw.Width.DWORD),
            VARIABLE,
            "243A 0000 4248 0000",
        ),
        (pkw.Rejection(7, 1082, 0, 5, FAULT_5.text, FAULT_5.short), VARIABLE, "743A 0000 0005"),
        (pkw.ArrayCountResponse(6, 947, 0, 64), VARIABLE, "63B3 0000 0040"),
    ],
)
def test_a_follower_answers_as_long_as_the_answer_needs(
    resp: pkw.PkwResponse, pkw_words: int | None, expected: str
) -> None:
    assert pkw.encode_response(resp, USS, LAYOUT, pkw_words) == words(expected)
    assert pkw.decode_response(words(expected), USS, LAYOUT) == resp


def test_a_text_and_a_name_element_are_as_long_as_they_are() -> None:
    """With a variable length a text travels whole (MASTERDRIVES Compendium, 8.1: with
    127 "parameter description elements and texts can also be transferred")."""
    name = b"Ramp-up time    "
    element = pkw.DescriptionResponse(3, 1120, 6, int.from_bytes(name[:4], "big"), name)
    data = pkw.encode_response(element, USS, LAYOUT, VARIABLE)
    assert len(data) == 4 + len(name)
    back = pkw.decode_response(data, USS, LAYOUT)
    assert isinstance(back, pkw.DescriptionResponse) and back.data == name


def test_what_answers_tell() -> None:
    word = pkw.ValueResponse(1, 52, 0, 7, pkw.Width.WORD)
    dword = pkw.ValueResponse(2, 1082, 0, 7, pkw.Width.DWORD)
    assert told(4, 3, word) is VARIABLE  # a fixed drive answers with its own length
    assert told(4, 4, word) == 4  # a variable drive would have answered 3 words
    assert told(4, 4, dword) == "?"  # 4 or variable carry a double word alike
    assert told(3, 3, word) == "?"  # 3 or variable carry a word alike
    assert told(3, 4, dword) is VARIABLE
    assert told(4, 2, pkw.NoResponse(0, 0, 0)) is VARIABLE
    assert told(4, 4, pkw.NoResponse(0, 0, 0)) == "?"


def test_auto_learns_keeps_and_forgets() -> None:
    length = PkwLength(AUTO)
    word = pkw.ValueResponse(1, 52, 0, 7, pkw.Width.WORD)
    dword = pkw.ValueResponse(2, 1082, 0, 7, pkw.Width.DWORD)
    assert (length.words, length.known) == (4, False)
    assert length.gate(word=True)[0] is Gate.LEARN  # a word's place is not known yet
    assert length.gate(word=False)[0] is Gate.SEND  # a double word travels alike
    assert not length.observe(4, 4, dword)  # tells nothing
    assert length.observe(4, 3, word)
    assert (length.words, length.known) == (VARIABLE, True)
    assert length.gate(word=True)[0] is Gate.SEND
    assert length.gate(word=True, text=True)[0] is Gate.SEND
    assert not length.observe(3, 3, word)  # agrees
    length.forget()
    assert (length.words, length.known) == (4, False)
    assert length.observe(4, 4, word) and length.words == 4


@pytest.mark.parametrize(
    ("words", "word", "text", "refused"),
    [
        (4, False, True, "a text needs a variable PKW length; the drive's is 4"),
        (3, False, True, "a text needs a variable PKW length; the drive's is 3"),
        (3, False, False, "a double word does not fit the drive's 3 PKW words"),
    ],
)
def test_what_a_known_length_cannot_carry_is_refused(
    words: int, word: bool, text: bool, refused: str
) -> None:
    length = PkwLength(AUTO)
    length.words, length.known = words, True
    assert length.gate(word=word, text=text) == (Gate.REFUSE, refused)
    assert length.gate(word=True)[0] is Gate.SEND


def test_a_configured_length_the_answers_contradict_refuses_changes() -> None:
    length = PkwLength(4)
    word = pkw.ValueResponse(1, 52, 0, 7, pkw.Width.WORD)
    assert length.known and length.gate(word=True)[0] is Gate.SEND
    assert length.observe(4, 3, word) and length.in_conflict and length.conflict is VARIABLE
    assert length.gate(word=True)[0] is Gate.REFUSE
    assert length.gate(word=False)[0] is Gate.REFUSE
    assert length.words == 4  # the configuration stands: nothing is guessed
    assert length.observe(4, 4, word) and not length.in_conflict
    assert length.gate(word=True)[0] is Gate.SEND


def test_a_configured_3_in_conflict_is_asked_again_once_the_drive_was_away() -> None:
    """A word in 3 words to 3 words fits 3 and variable alike: it neither clears a conflict
    told before (a double word in 4 words) nor tells one. No answer tells a fixed-3 drive
    apart, so the conflict is asked again once the drive was away."""
    length = PkwLength(3)
    word = pkw.ValueResponse(1, 52, 0, 7, pkw.Width.WORD)
    dword = pkw.ValueResponse(2, 1082, 0, 7, pkw.Width.DWORD)
    assert not length.observe(3, 3, word) and not length.in_conflict
    assert length.observe(3, 4, dword) and length.conflict is VARIABLE
    assert not length.observe(3, 3, word) and length.in_conflict
    length.forget()
    assert not length.in_conflict and length.words == 3
    assert length.observe(3, 4, dword) and length.in_conflict  # told again


def test_a_configured_4_conflict_stands_through_answers_that_fit_both() -> None:
    """A variable drive configured 4: its word answers (3 words to 4) tell the conflict;
    its double words in 4 words to 4 fit both and must not clear it, or the conflict and
    its warning come and go with every answer and changes slip out in between."""
    length = PkwLength(4)
    word = pkw.ValueResponse(1, 52, 0, 7, pkw.Width.WORD)
    dword = pkw.ValueResponse(2, 304, 0, 0x43660000, pkw.Width.DWORD)
    assert length.observe(4, 3, word) and length.in_conflict
    for _ in range(3):
        assert not length.observe(4, 4, dword)
        assert length.in_conflict and length.gate(word=False)[0] is Gate.REFUSE
        assert not length.observe(4, 3, word)  # told once, not again
    length.forget()  # the drive away: a configured 4 is told apart by its next word
    assert length.in_conflict


def test_a_learned_target_splits_answers_by_their_length() -> None:
    target = DriveTarget.create("uss", 1)
    assert target.learn and target.shape == BlockShape(4, 2)
    assert SerialCarrier(target).response_shape(10) == BlockShape(None, 2)
    fixed = DriveTarget.create("uss", 1, pkw_words=4)
    assert SerialCarrier(fixed).response_shape(12) == BlockShape(4, 2)
    assert SerialCarrier(fixed).response_shape(10) == BlockShape(
        3, 2
    )  # the other fixed length: told apart
    assert SerialCarrier(fixed).response_shape(16) == BlockShape(4, 2)  # anything else fails there
    learned = target.with_pkw_words(VARIABLE)
    request = SerialCarrier(learned).telegram(word_change(700, 5))
    assert request == frame(SerialCarrier(learned).address, words("22BC 0000 0005") + bytes(4))
    assert SerialCarrier(learned).pkw_words_of(request) == 3
    # a text checks and shows as the variable block it needs, before the length is known
    text = SerialCarrier(target).telegram(pkw.write_text(USS, 199, b"FAN-12"))
    assert text[3:13] == words("F0C7 0000") + b"FAN-12"


def test_a_length_as_people_configure_it() -> None:
    assert [shown(w) for w in (AUTO, VARIABLE, 3, 4, 0)] == [
        "auto", "127 (variable)", "3", "4", "0",
    ]  # fmt: skip


def test_a_rejection_with_a_fault_number_tells_a_fixed_4_drive() -> None:
    """A variable drive answers a fault number in one PWE word (MICROMASTER 420 Reference
    Manual, 3.3.5: 743A 0000 0005, 3 words); in 4 words to 4 words it is a fixed-4
    drive. "No change rights" carries no number: it tells nothing."""
    fault = pkw.decode_response(words("743A 0000 0000 0005"), USS, LAYOUT)
    assert isinstance(fault, pkw.Rejection) and fault.fault == 5
    assert told(4, 4, fault) == 4
    no_rights = pkw.decode_response(words("843A 0000 0000 0000"), USS, LAYOUT)
    assert isinstance(no_rights, pkw.Rejection) and no_rights.fault is None
    assert told(4, 4, no_rights) == "?"


def test_an_answer_that_fits_both_tells_a_configured_length_nothing() -> None:
    """A double word in 4 words to 4 words fits a variable drive as well as a fixed-4
    one: for a drive configured variable it is no conflict, and no agreement either."""
    length = PkwLength(VARIABLE)
    dword = pkw.ValueResponse(2, 1082, 0, 0x42480000, pkw.Width.DWORD)
    assert not length.observe(4, 4, dword)
    assert not length.in_conflict and length.words is VARIABLE


def test_a_fixed_3_drive_back_from_away_has_its_conflict_asked_again() -> None:
    """The carrier tells the conflict's end when the drive was away (the metric and the log
    follow what it tells); nothing when there was none to end."""
    carrier = SerialCarrier(DriveTarget.create("uss", 1, pkw_words=3))
    assert carrier.forget() is None
    length = carrier.length
    assert length is not None
    dword = pkw.ValueResponse(2, 1082, 0, 7, pkw.Width.DWORD)
    assert length.observe(3, 4, dword) and length.in_conflict  # as an answer told it
    told = carrier.forget()
    assert told is not None and not told.in_conflict and told.configured == 3
    assert carrier.forget() is None
    fixed_4 = SerialCarrier(DriveTarget.create("uss", 1, pkw_words=4))
    assert fixed_4.length is not None and fixed_4.length.observe(4, 3, dword)
    assert fixed_4.forget() is None and fixed_4.length.in_conflict  # its words tell it
