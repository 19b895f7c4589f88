"""A USS drive's PKW length, told by its answers: fixed 3, fixed 4 or variable (127).

Every Siemens USS drive leaves the factory with a variable PKW length
(SINAMICS G120X Operating Instructions, "USS parameter channel": p2023
factory setting 127; MICROMASTER 440 Parameter List, P2013 default 127;
SINAMICS V20 Operating Instructions, P2013 factory default 127). Where the
length decides a value's place, a wrong guess writes the wrong value: with 4
fixed words a word travels in PWE2, with a variable length in PWE1.

What the answers tell (SINAMICS S110 Function Manual, "Communication using
USS", parameter value PWE): a drive with a fixed length answers only
requests of that length, always with that many words; a variable drive
answers with as many words as the answer needs, one PWE word for a word
value, a fault number or a count. So an answer of another length than the
request is a variable drive, and a word-sized answer in 4 words to 4 words
is a fixed-4 drive. A double word in 4 words fits both 4 and variable (and
both carry it alike); a word in 3 words to 3 words fits both 3 and variable
(and both carry a word alike).

:class:`PkwLength` keeps what a drive's answers told against what was
configured (``AUTO``: learn it), and says how a request may go out.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final, Literal

from pkwbus.protocol.pkw.fields import Width
from pkwbus.protocol.pkw.responses import (
    ArrayCountResponse,
    PkwResponse,
    Rejection,
    ValueResponse,
)

__all__ = [
    "AUTO",
    "UNKNOWN_SEND_WORDS",
    "VARIABLE",
    "Gate",
    "PkwLength",
    "PkwSetting",
    "PkwWords",
    "shown",
    "told",
]

AUTO: Final = "auto"
VARIABLE: Final = None  # a variable PKW length (USS code 127), as BlockShape has it

PkwWords = int | None  # 0, 3 or 4 fixed words; None: variable
PkwSetting = int | None | Literal["auto"]

# The length a request goes out with while a drive's length is not known: both a
# fixed-4 drive and a variable one answer it (a fixed-3 drive does not answer).
UNKNOWN_SEND_WORDS: Final = 4


def shown(words: PkwSetting) -> str:
    """A PKW length as people configure it: 3, 4, 127 (variable) or auto."""
    if words == AUTO:
        return AUTO
    return "127 (variable)" if words is None else str(words)


def _word_sized(response: PkwResponse) -> bool:
    """An answer a variable drive sends with one PWE word (a description element's
    size is not known from a fixed block, so it tells nothing there)."""
    if isinstance(response, ValueResponse):
        return response.width is Width.WORD
    if isinstance(response, Rejection):
        return response.fault is not None
    return isinstance(response, ArrayCountResponse)


def told(sent_words: int, answer_words: int, response: PkwResponse) -> PkwWords | Literal["?"]:
    """The PKW length an answer shows; ``"?"`` when it fits more than one.

    ``sent_words``: the PKW words of the request it answers; ``answer_words``:
    the PKW words of the answer (its length by LGE, less its process data).
    """
    if answer_words != sent_words:
        return VARIABLE
    if answer_words == 4 and _word_sized(response):
        return 4
    return "?"


class Gate(enum.Enum):
    """Whether a request may go out to a drive now, by what its PKW length is known to be."""

    SEND = "send"
    LEARN = "learn"  # read the parameter first: its answer tells the length
    REFUSE = "refuse"  # the configured length contradicts the drive's answers


@dataclass
class PkwLength:
    """What a drive's PKW length is: configured, and as its answers told it.

    ``configured`` is 0, 3, 4, None (variable) or ``AUTO``. ``words`` is the
    length requests go out with now; ``known`` whether it was configured or
    learned (not a guess); ``conflict`` the length the drive's answers showed
    against a configured one, None while they agree.
    """

    configured: PkwSetting
    words: PkwWords = UNKNOWN_SEND_WORDS
    known: bool = False
    conflict: PkwWords | Literal["?"] = "?"

    def __post_init__(self) -> None:
        if not isinstance(self.configured, str):
            self.words, self.known = self.configured, True

    @property
    def in_conflict(self) -> bool:
        return self.conflict != "?"

    def forget(self) -> None:
        """The drive was away: what it told may have changed (a learned length is asked again)."""
        if self.configured == AUTO:
            self.words, self.known = UNKNOWN_SEND_WORDS, False
        elif self.configured == 3:
            # No answer tells a fixed-3 drive from a variable one (a word fits both): a
            # conflict it showed is asked again once it is back (set to 3 meanwhile, say).
            self.conflict = "?"

    def observe(self, sent_words: int, answer_words: int, response: PkwResponse) -> bool:
        """Take what an answer told; True when ``words`` or ``conflict`` changed."""
        verdict = told(sent_words, answer_words, response)
        if self.configured != AUTO:
            if isinstance(verdict, str):
                # Fits more than one length (a double word in 4 words to 4, a word in 3 to
                # 3): neither agreement nor conflict. Taken for agreement, it cleared a
                # conflict that the next word's answer told again, over and over.
                return False
            conflict: PkwWords | Literal["?"] = "?" if verdict == self.configured else verdict
            changed = conflict != self.conflict
            self.conflict = conflict
            return changed
        if isinstance(verdict, str):
            return False
        changed = not self.known or verdict != self.words
        self.words, self.known = verdict, True
        return changed

    def gate(self, *, word: bool, text: bool = False) -> tuple[Gate, str]:
        """May a change of a word (``word``), a double word or a text go out now, and why not?

        A double word travels alike with 4 words and variable length, and a
        fixed-3 drive does not answer a 4-word request: it may go out before
        the length is known, but never to a fixed-3 drive. A word's place
        depends on the length, so it waits until the length is known; a text
        needs a variable length.
        """
        if self.in_conflict:
            return Gate.REFUSE, "conflict"
        if not self.known:
            return (Gate.LEARN, "") if word or text else (Gate.SEND, "")
        if text and self.words is not None:
            return Gate.REFUSE, f"a text needs a variable PKW length; the drive's is {self.words}"
        if not word and not text and self.words == 3:
            return Gate.REFUSE, "a double word does not fit the drive's 3 PKW words"
        return Gate.SEND, ""
