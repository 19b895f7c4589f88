"""What the planner knows of how one drive's PKW jobs travel: its carrier.

A carrier is one way a PKW job travels (:mod:`pkwbus.master.carriers`): a
serial telegram (FC, USS), a PPO's PKW slot (PROFIBUS DP), PROFIdrive data
record 47 (DP-V1). It builds a job's transaction - the request as it goes
out, and how its answer is decoded, once - and says what the planner must
know to plan: how many parameters one request carries, whether a text
travels, whether a change must be read first, whether the drive's health is
told by the wire. The planner never knows which bus it serves (the rule of
h11: the state machine does not know its transport).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from pkwbus.master.planning.answers import ExchangeResult
from pkwbus.master.planning.transaction import BatchTransaction, PkwTransaction, ProbeTransaction
from pkwbus.protocol import pkw
from pkwbus.protocol.pkw.dialects import Dialect
from pkwbus.protocol.pkw.length import Gate, PkwLength
from pkwbus.protocol.values.types import ValueType

__all__ = ["Carrier", "Item", "Preview", "Probe", "Transaction"]

Transaction = PkwTransaction | BatchTransaction | ProbeTransaction


@dataclass(frozen=True, slots=True)
class Item:
    """One parameter of a request: the PKW request, and the type its value is known by
    (a change goes out in it; None: not known)."""

    request: pkw.PkwRequest
    vtype: ValueType | None = None


@dataclass(frozen=True, slots=True)
class Preview:
    """A request as its carrier would send it now (a dry run shows these bytes); ``note``
    says what of them is decided only when it is sent (empty: nothing)."""

    telegram: bytes
    note: str = ""


@dataclass(frozen=True, slots=True)
class Probe:
    """The shortest request a down drive answers, to see whether it does; ``words`` tells
    the carrier, when the answer comes, what length it was sent with."""

    telegram: bytes
    words: int | None = None


class Carrier(Protocol):
    """One drive's way for its PKW jobs, as the planner sees it."""

    @property
    def address(self) -> int:
        """The address its answers come from (the wire checks them against it)."""
        ...

    @property
    def dialect(self) -> Dialect: ...

    @property
    def texts(self) -> bool:
        """Whether a text request travels (not in the 4 PKW words of a PPO)."""
        ...

    @property
    def repeats_answers(self) -> bool:
        """Whether the drive may answer a new request with its previous answer (FC, USS):
        a change then goes out after a read of its parameter."""
        ...

    @property
    def tells_health(self) -> bool:
        """Whether the wire tells the drive's health (a DP slave's state): missing answers
        then never take it down, and it is never probed."""
        ...

    def room(self, count: int) -> bool:
        """Whether ``count`` parameters go out in one request (a PKW request carries one)."""
        ...

    def refuses(self, request: pkw.PkwRequest) -> str:
        """Why ``request`` cannot travel this way; empty when it can."""
        ...

    def preview(self, item: Item) -> Preview:
        """``item``'s request as it would go out now, built as :meth:`transaction` builds
        it; LocalProtocolError for what this way cannot carry (what :meth:`refuses`
        says, or what does not encode)."""
        ...

    def transaction(
        self, items: Sequence[Item], *, retries: int, deadline: float, stale: bytes | None = None
    ) -> Transaction:
        """The transaction of ``items`` (one, or several where :meth:`room` allows);
        LocalProtocolError for what this way cannot carry."""
        ...

    def probe(self) -> Probe | None:
        """The next probe of a down drive (None: it is never probed)."""
        ...

    def status(self, result: ExchangeResult) -> tuple[int, int | None] | None:
        """The status word and main actual value of a probe's answer, where it has them."""
        ...

    def probed(self, probe_words: int | None, result: ExchangeResult) -> PkwLength | None:
        """A probe was answered: what it told of how requests go out (None: nothing new)."""
        ...

    def heard(self, tx: PkwTransaction) -> PkwLength | None:
        """An answer ``tx`` decoded: what it told of how requests go out (None: nothing)."""
        ...

    def forget(self) -> PkwLength | None:
        """The drive went down: what its answers told is asked again."""
        ...

    def gate(self, request: pkw.PkwRequest) -> tuple[Gate, str]:
        """Whether a change may go out now: send it, read its parameter first to learn how
        it goes out, or refuse it (with why)."""
        ...
