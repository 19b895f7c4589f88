"""What the carriers of a PROFIBUS DP slave share: the slave's state is its health.

The DP wire tells the planner whether a slave is in data exchange, so the
slave is never probed, its answers teach nothing of how requests go out, and
a change needs no read first (its PKW slot waits for AK 0; data record 47
answers each request alone).
"""

from __future__ import annotations

from pkwbus.master.planning.answers import ExchangeResult
from pkwbus.master.planning.carrier import Probe
from pkwbus.master.planning.transaction import PkwTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.length import Gate, PkwLength

__all__ = ["SlaveHealth"]


class SlaveHealth:
    """The part of a DP slave's carrier that its state answers for."""

    tells_health = True

    def probe(self) -> Probe | None:
        return None

    def status(self, result: ExchangeResult) -> tuple[int, int | None] | None:
        return None

    def probed(self, probe_words: int | None, result: ExchangeResult) -> PkwLength | None:
        return None

    def heard(self, tx: PkwTransaction) -> PkwLength | None:
        return None

    def forget(self) -> PkwLength | None:
        return None

    def gate(self, request: pkw.PkwRequest) -> tuple[Gate, str]:
        return Gate.SEND, ""
