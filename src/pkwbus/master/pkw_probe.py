"""Ask a USS drive once what its PKW length is: a word read, and the length of its answer.

For ``pkwbus scan`` and ``pkwbus check-config --probe``. The read goes out
with the target's PKW length (4 words while a length is learned: both a
fixed-4 and a variable drive answer that), and the answer's length tells
(:func:`pkwbus.protocol.pkw_length.told`). The parameter read is r0002, a
word on the Siemens drives (MICROMASTER 440 Parameter List: r0002 "Drive
state", U16); a drive without it answers with a rejection, whose fault
number is a word as well, so it tells the same.
"""

from __future__ import annotations

import asyncio
from typing import Final, Literal

from pkwbus.master.line import Line
from pkwbus.master.target import DriveTarget
from pkwbus.master.transaction import PkwTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw_length import PkwWords, told

__all__ = ["LENGTH_PNU", "NO_ANSWER", "ask_pkw_length"]

LENGTH_PNU: Final = 2
NO_ANSWER: Final = "no answer"


async def ask_pkw_length(
    line: Line, target: DriveTarget, *, retries: int, deadline: float
) -> PkwWords | Literal["?", "no answer"]:
    """The PKW length the drive's answer shows (None: variable); ``"?"`` when it fits more
    than one (a double word), :data:`NO_ANSWER` when no answer came (or there is no PKW)."""
    if not target.has_pkw:
        return NO_ANSWER
    tx = PkwTransaction(
        target, pkw.read(target.dialect, LENGTH_PNU), retries=retries, deadline=deadline
    )
    sent = target.pkw_words_of(tx.telegram)
    loop = asyncio.get_running_loop()
    while True:
        result = await line.exchange(target, tx.telegram)
        outcome = tx.feed(result, loop.time())
        answer, response = tx.answer_pkw, tx.response
        if answer is not None and response is not None and outcome is not None:
            return told(sent, len(answer) // 2, response)
        if outcome is not None:
            return NO_ANSWER
