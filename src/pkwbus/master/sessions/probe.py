"""Ask a drive on a command's line: what its PKW length is (USS: a word read, and the
length of its answer), and how it describes a parameter (AK 4).

For ``pkwbus scan`` and ``pkwbus check-config --probe``: each a job of the
session's runner (:class:`pkwbus.master.sessions.session.LineSession`).
The read goes out with the target's PKW length (4 words while a length is learned: both a
fixed-4 and a variable drive answer that), and the answer's length tells
(:func:`pkwbus.protocol.pkw.length.told`). The parameter read is r0002, a
word on the Siemens drives (MICROMASTER 440 Parameter List: r0002 "Drive
state", U16); a drive without it answers with a rejection, whose fault
number is a word as well, so it tells the same.
"""

from __future__ import annotations

import asyncio
from typing import Final, Literal

from pkwbus.master.carriers import SerialCarrier
from pkwbus.master.planning.outcomes import Answered, Rejected
from pkwbus.master.sessions.session import LineSession
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.descriptions import (
    DATA_TYPE,
    DriveDescription,
    elements_to_read,
    form_of,
    read_elements,
)
from pkwbus.protocol.pkw.length import PkwWords, told

__all__ = ["LENGTH_PNU", "NO_ANSWER", "ask_description", "ask_pkw_length"]

LENGTH_PNU: Final = 2
NO_ANSWER: Final = "no answer"


async def ask_pkw_length(
    session: LineSession, drive: str, target: DriveTarget, *, deadline: float
) -> PkwWords | Literal["?", "no answer"]:
    """The PKW length the drive's answer shows (None: variable); ``"?"`` when it fits more
    than one (a double word), :data:`NO_ANSWER` when no answer came (or there is no PKW)."""
    if not target.has_pkw:
        return NO_ANSWER
    request = pkw.read(target.dialect, LENGTH_PNU)
    tally = (await session.job(drive, request, deadline)).tally
    if tally is None or tally.response is None or tally.answer_words is None:
        return NO_ANSWER
    sent = SerialCarrier(target).pkw_words_of(tally.sent)
    return told(sent, tally.answer_words, tally.response)


async def ask_description(
    session: LineSession, drive: str, target: DriveTarget, pnu: int, *, timeout: float
) -> DriveDescription | Literal["no answer"] | None:
    """How the drive describes ``pnu`` (None: it has no description of it), or
    :data:`NO_ANSWER`; None too where its dialect has no description elements."""
    form = form_of(target.dialect)
    if form is None or not target.has_pkw:
        return None
    found: dict[int, pkw.DescriptionResponse | None] = {}
    loop = asyncio.get_running_loop()
    for element in elements_to_read(limits=True):
        request = pkw.read_description(target.dialect, pnu, element)
        deadline = loop.time() + timeout
        outcome = (await session.job(drive, request, deadline)).outcome
        response = outcome.response if isinstance(outcome, Answered) else None
        if isinstance(response, pkw.DescriptionResponse):
            found[element] = response
        elif not isinstance(outcome, Answered | Rejected):
            return NO_ANSWER
        elif element == DATA_TYPE:
            return None  # refused: the drive has no description of it
        else:
            found[element] = None
    said = read_elements(form, found)
    return None if said.empty else said
