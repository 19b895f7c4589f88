"""PKW jobs in the PKW words of a PROFIBUS DP slave's PPO (its parameter slot).

The slave's slot (:class:`~pkwbus.protocol.profibus.dp.ppo.PkwSlot`, one a
slave, made here and cycled by the DP wire) puts the job's request in every
PPO-write until the job is over, as the bytes this carrier encoded once for the
job's transaction (the dry run's bytes), and decodes each PPO-read once. The DP wire
hands each PPO-read that came while the slot carried the job to the planner
as it came (a :class:`~pkwbus.master.planning.answers.Reply`); the job's
transaction gives it to this carrier's decoder, which takes what the slot
read of those bytes: no PPO-read is decoded twice, and the wire builds no
answer. The slot waits for the slave's AK 0 before each new request, so no
stale answer is taken for a new one and a change needs no read first; the
slave's state, told by the wire, is its health. Its channel answers every
cycle: "not yet" is its way of working (the transaction's ``every_cycle``).
"""

from __future__ import annotations

from collections.abc import Sequence

from pkwbus.master.carriers.slave import SlaveHealth
from pkwbus.master.planning.answers import PkwAnswer
from pkwbus.master.planning.carrier import Item, Preview
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.profibus.dp.ppo import PkwSlot, PpoType, encode_ppo_write

__all__ = ["SlotCarrier"]


class SlotCarrier(SlaveHealth):
    """A DP slave's PKW slot: its station address, PPO type and dialect."""

    texts = False  # a text does not fit the 4 PKW words of a PPO
    repeats_answers = False  # the slot waits for AK 0 before a new request

    def __init__(self, address: int, ppo: PpoType, dialect: Dialect) -> None:
        self.address = address
        self.ppo = ppo
        self.dialect = dialect
        self.slot: PkwSlot | None = None  # the slot the wire cycles now (None: not yet)

    def new_slot(self) -> PkwSlot:
        """A slot afresh (the slave started, or started again): the one decoded from now."""
        self.slot = PkwSlot(self.ppo, self.dialect)
        return self.slot

    def room(self, count: int) -> bool:
        return count == 1

    def refuses(self, request: pkw.PkwRequest) -> str:
        return "a text does not fit the 4 PKW words of a PPO" if request.text else ""

    def preview(self, item: Item) -> Preview:
        """The PPO-write the slot puts the request in (its PZD as the slot sends them)."""
        return Preview(self._write(item.request))

    def _write(self, request: pkw.PkwRequest) -> bytes:
        why = self.refuses(request)
        if why:
            raise LocalProtocolError(why)
        return encode_ppo_write(self.ppo, self.dialect, request)

    def transaction(
        self, items: Sequence[Item], *, retries: int, deadline: float, stale: bytes | None = None
    ) -> PkwTransaction:
        (item,) = items
        request = item.request
        return PkwTransaction(
            self.dialect, request, self._write(request), self.decode, retries=retries,
            deadline=deadline, stale=stale, every_cycle=True,
        )  # fmt: skip

    def decode(self, data: bytes, duration: float) -> PkwAnswer:
        """A PPO-read as its slot read it: the PKW answer, and whether it may still answer
        an earlier request (no AK 0 seen since). Its status word is not repeated here: the
        wire tells it with every cycle's exchange."""
        update = self.slot.update if self.slot is not None else None
        if update is None or update.inputs is not data:
            return PkwAnswer(
                None, b"", None, None, duration, why="a PPO-read its slot did not take"
            )
        if update.garbled is not None:
            return PkwAnswer(None, b"", None, None, duration, why=update.garbled.why)
        answer = update.answer
        if answer is None:
            return PkwAnswer(None, b"", None, None, duration, why="no PKW answer")
        cut = data[: 2 * self.ppo.pkw_words]
        return PkwAnswer(answer.response, cut, None, None, duration, earlier=answer.earlier)
