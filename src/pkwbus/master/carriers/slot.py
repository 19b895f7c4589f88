"""PKW jobs in the PKW words of a PROFIBUS DP slave's PPO (its parameter slot).

The job's request is not built here: the slave's slot
(:class:`~pkwbus.protocol.profibus.dp.ppo.PkwSlot`, in the DP wire) puts it
in every PPO-write until the job is over, and decodes each PPO-read once -
its PKW answer and its status word - into the answer the job judges. The
slot waits for the slave's AK 0 before each new request, so no stale answer
is taken for a new one and a change needs no read first; the slave's state,
told by the wire, is its health.
"""

from __future__ import annotations

from collections.abc import Sequence

from pkwbus.master.carriers.slave import SlaveHealth
from pkwbus.master.planning.answers import PkwAnswer
from pkwbus.master.planning.carrier import Item
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.profibus.dp.ppo import PpoType, decode_ppo_read

__all__ = ["SlotCarrier"]


class SlotCarrier(SlaveHealth):
    """A DP slave's PKW slot: its station address, PPO type and dialect."""

    texts = False  # a text does not fit the 4 PKW words of a PPO
    repeats_answers = False  # the slot waits for AK 0 before a new request

    def __init__(self, address: int, ppo: PpoType, dialect: Dialect) -> None:
        self.address = address
        self.ppo = ppo
        self.dialect = dialect

    def room(self, count: int) -> bool:
        return count == 1

    def refuses(self, request: pkw.PkwRequest) -> str:
        return "a text does not fit the 4 PKW words of a PPO" if request.text else ""

    def transaction(
        self, items: Sequence[Item], *, retries: int, deadline: float, stale: bytes | None = None
    ) -> PkwTransaction:
        (item,) = items
        return PkwTransaction(
            self.dialect, item.request, b"", self.decode, retries=retries, deadline=deadline,
            stale=stale,
        )  # fmt: skip

    def decode(self, data: bytes, duration: float) -> PkwAnswer:
        """A PPO-read as the slot would decode it (the DP wire hands the slot's answers over
        decoded; this decodes one that came as bytes)."""
        try:
            read = decode_ppo_read(self.ppo, self.dialect, data)
        except RemoteProtocolError as exc:
            return PkwAnswer(None, b"", None, None, duration, cyclic=True, why=str(exc))
        if read.pkw is None:
            return PkwAnswer(None, b"", None, None, duration, cyclic=True, why="no PKW words")
        words = read.pzd
        status = words[0] if words else None
        mav = words[1] if len(words) > 1 else None
        cut = data[: 2 * self.ppo.pkw_words]
        return PkwAnswer(read.pkw, cut, status, mav, duration, cyclic=True)
