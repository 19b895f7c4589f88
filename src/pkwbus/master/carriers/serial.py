"""PKW jobs in serial telegrams: the Danfoss FC protocol and Siemens USS.

A request is a whole telegram (STX, LGE, ADR, PKW, the control word with bit
10 = 0 and a reference of 0, BCC); a reply's data is split by the drive's
block shape and its PKW part decoded, once, with its status word and main
actual value beside it. A drive may answer a new request with its previous
answer while it works on it (USS specification; SINAMICS manuals): a change
goes out after a read of its parameter.

A USS drive's PKW length (``pkw_words: auto``) is learned from its answers
(:mod:`pkwbus.protocol.pkw.length`): requests then go out with it; a change
of a word waits until it is known (its place in PWE depends on it), and none
goes out while the drive's answers contradict a configured length. While it
is not known, every other probe of a down drive has 3 PKW words: a fixed-3
drive answers no 4-word request (SINAMICS S110 Function Manual, 9.5).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from pkwbus.master.planning.answers import ExchangeResult, PkwAnswer, Reply
from pkwbus.master.planning.carrier import Item, Preview, Probe
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.master.target import DriveTarget
from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.pkw.fields import Width
from pkwbus.protocol.pkw.length import Gate, PkwLength, shown
from pkwbus.protocol.pzd import MONITORING_CTW
from pkwbus.protocol.serial.telegram import (
    FC_PARAMETER,
    FC_PROCESS,
    BlockShape,
    encode_block,
    fc_adr,
    frame,
    split_block,
    uss_adr,
)

__all__ = ["SerialCarrier"]

_PROBE_SHORT = 3  # PKW words of every other probe while a learned length is not known
_KEPT = 512  # telegrams kept built (a drive's polls); more, and they are built afresh
# PKW answers kept decoded (a parameter that holds its value answers the same bytes at every
# poll); more, and they are decoded afresh.
_KEPT_ANSWERS = 256


class SerialCarrier:
    """A drive on an FC or USS line: its telegrams, and (USS) its PKW length."""

    texts = True
    repeats_answers = True
    tells_health = False

    def __init__(self, target: DriveTarget) -> None:
        self.target = target
        self.fc = target.protocol is Bus.FC
        uss = target.protocol is Bus.USS and target.has_pkw
        self.length = PkwLength(target.pkw_setting) if uss else None
        # The ADR byte of its telegrams.
        self.address = (
            fc_adr(target.address, target.fc_format) if self.fc else uss_adr(target.address)
        )
        self._telegrams: dict[pkw.PkwRequest, bytes] = {}  # requests as they go out now
        # PKW answers as decoded by the target now (a response is immutable: one serves
        # every answer of the same bytes).
        self._decoded: dict[bytes, pkw.PkwResponse] = {}
        self._probes = 0

    @property
    def dialect(self) -> Dialect:
        return self.target.dialect

    def room(self, count: int) -> bool:
        return count == 1

    def refuses(self, request: pkw.PkwRequest) -> str:
        return ""

    def telegram(self, request: pkw.PkwRequest) -> bytes:
        """``request``'s telegram as it goes out now (built once while the shape stands);
        LocalProtocolError for one that cannot."""
        built = self._telegrams.get(request)
        if built is None:
            if len(self._telegrams) >= _KEPT:
                self._telegrams.clear()
            built = self._telegrams[request] = self._build(self.target, request)
        return built

    def preview(self, item: Item) -> Preview:
        return Preview(self.telegram(item.request))

    def _build(self, target: DriveTarget, request: pkw.PkwRequest) -> bytes:
        """The whole request telegram: PKW, control word with bit 10 = 0, reference 0."""
        words = target.shape.pkw_words
        if request.text and (self.fc or target.learn):
            words = None  # a text travels in a block as long as it is
        data = pkw.encode_request(request, target.dialect, target.ind_layout, words)
        return frame(self.address, encode_block(data, _idle(target.shape)))

    def probe_telegram(self, target: DriveTarget | None = None) -> bytes:
        """The shortest telegram the drive answers: process data only (FC) or PKW AK 0
        (of ``target``: the drive with another PKW length)."""
        target = target or self.target
        if self.fc:
            return frame(self.address, encode_block(b"", (MONITORING_CTW, 0)))
        if not target.has_pkw:
            return frame(self.address, encode_block(b"", _idle(target.shape)))
        return self._build(target, pkw.none_request(target.dialect))

    def response_shape(self, data_len: int) -> BlockShape:
        """The shape to split a response of ``data_len`` bytes by.

        USS: a drive whose length is learned, or variable, is split by its
        process data alone (the PKW part is the rest, by LGE). A fixed length
        also takes an answer of the other fixed length, 3 or 4 words: that is
        the drive's own length telling against the configured one, which the
        planner reports (its value placed by its LGE); anything else is split
        by the configured shape, and fails there.
        """
        shape = self.target.shape
        if self.fc:
            if data_len == 4:
                return FC_PROCESS
            return BlockShape(None, 2) if data_len != 12 else FC_PARAMETER
        pzd = shape.pzd_words
        if self.target.learn or shape.pkw_words is None:
            return BlockShape(None, pzd)
        if shape.pkw_words and data_len in (2 * (3 + pzd), 2 * (4 + pzd)):
            return BlockShape(data_len // 2 - pzd, pzd)
        return shape

    def pkw_words_of(self, telegram: bytes) -> int:
        """The PKW words of one of this drive's request telegrams (STX to BCC)."""
        return (len(telegram) - 4) // 2 - self.target.shape.pzd_words

    def transaction(
        self, items: Sequence[Item], *, retries: int, deadline: float, stale: bytes | None = None
    ) -> PkwTransaction:
        (item,) = items
        request = item.request
        return PkwTransaction(
            self.target.dialect, request, self.telegram(request), self.decode, retries=retries,
            deadline=deadline, stale=stale,
        )  # fmt: skip

    def decode(self, data: bytes, duration: float) -> PkwAnswer:
        """A reply's data: its block split by the drive's shape, its PKW part decoded."""
        target = self.target
        try:
            block = split_block(data, self.response_shape(len(data)))
        except RemoteProtocolError as exc:
            return PkwAnswer(None, b"", None, None, duration, why=str(exc))
        answer = block.pkw
        response = self._decoded.get(answer)
        if response is None:
            try:
                response = pkw.decode_response(answer, target.dialect, target.ind_layout)
            except RemoteProtocolError as exc:
                return PkwAnswer(
                    None, answer, block.status_word, block.main_actual, duration, why=str(exc)
                )
            if len(self._decoded) >= _KEPT_ANSWERS:
                self._decoded.clear()
            self._decoded[answer] = response
        return PkwAnswer(response, answer, block.status_word, block.main_actual, duration)

    # ------------------------------------------------------------ probes

    def probe(self) -> Probe | None:
        self._probes += 1
        length, target = self.length, self.target
        if length is None or length.known or not target.learn or self._probes % 2:
            return Probe(self.probe_telegram(target))
        short = target.with_pkw_words(_PROBE_SHORT)
        return Probe(self.probe_telegram(short), _PROBE_SHORT)

    def status(self, result: ExchangeResult) -> tuple[int, int | None] | None:
        if not isinstance(result, Reply):
            return None
        data = result.data
        try:
            block = split_block(data, self.response_shape(len(data)))
        except RemoteProtocolError:
            return None
        return (block.pzd[0], block.main_actual) if block.pzd else None

    def probed(self, probe_words: int | None, result: ExchangeResult) -> PkwLength | None:
        """A 3-word probe answered: 3 words back is a fixed-3 drive (its 4-word requests went
        unanswered), any other length a variable one."""
        length = self.length
        if length is None or length.known or probe_words != _PROBE_SHORT:
            return None
        if not isinstance(result, Reply):
            return None
        answer_words = len(result.data) // 2 - self.target.shape.pzd_words
        if answer_words == _PROBE_SHORT:
            length.words, length.known = _PROBE_SHORT, True
        else:
            length.observe(_PROBE_SHORT, answer_words, pkw.NoResponse(0, 0, 0))
        return self._retarget()

    # ------------------------------------------------------- PKW length

    def heard(self, tx: PkwTransaction) -> PkwLength | None:
        answer, response = tx.answer_pkw, tx.response
        length = self.length
        if answer is None or response is None or length is None:
            return None
        sent = self.pkw_words_of(tx.telegram)
        if not length.observe(sent, len(answer) // 2, response):
            return None
        return self._retarget()

    def forget(self) -> PkwLength | None:
        """The drive was away: a learned length is learned again, and a configured one's
        conflict that no answer clears (a fixed 3's) asked again; what is known of it now,
        when that changed."""
        length = self.length
        if length is None or (self.target.learn and not length.known):
            return None
        was = length.conflict
        length.forget()
        if not self.target.learn and length.conflict == was:
            return None
        return self._retarget()

    def _retarget(self) -> PkwLength | None:
        """Requests go out with the PKW length as known now (a learned one); a copy of what
        is known of it now."""
        length = self.length
        if length is None:
            return None
        if self.target.learn and length.words != self.target.shape.pkw_words:
            self.target = self.target.with_pkw_words(length.words)
            self._telegrams.clear()
            self._decoded.clear()
        return replace(length)

    def gate(self, request: pkw.PkwRequest) -> tuple[Gate, str]:
        length = self.length
        if length is None or (not request.is_write and not request.text):
            return Gate.SEND, ""
        word = request.width is Width.WORD and not request.text
        gate, why = length.gate(word=word, text=bool(request.text))
        if gate is Gate.REFUSE and length.in_conflict:
            conflict = length.conflict
            told = "?" if isinstance(conflict, str) else shown(conflict)
            why = (
                f"the drive answers with a PKW length of {told}, the configuration says"
                f" {shown(length.configured)}: no change until they agree (pkw_words)"
            )
        return gate, why


def _idle(shape: BlockShape) -> tuple[int, ...]:
    """The PZD of a request: control word with bit 10 = 0 (never take control), reference 0."""
    return (MONITORING_CTW,) + (0,) * (shape.pzd_words - 1) if shape.pzd_words else ()
