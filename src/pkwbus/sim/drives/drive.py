"""One simulated drive: model, parameters, process data, PKW lag, and the keypad (LCP) a
person at the drive sets values with (:meth:`SimDrive.keypad`, logged on the
``pkwbus.sim`` logger).

Raises :class:`~pkwbus.protocol.errors.RemoteProtocolError` for a request whose PKW part
has the wrong length.
"""

from __future__ import annotations

import logging
import random
from collections import deque
from dataclasses import dataclass, replace

from pkwbus.protocol import pkw
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw import PkwResponse, Rejection, TextResponse, ValueResponse, Width
from pkwbus.protocol.pkw.dialects import Command, Dialect, IndLayout, Reply
from pkwbus.protocol.pzd import Profile, takes_control
from pkwbus.protocol.serial.telegram import BlockShape, encode_block, split_block
from pkwbus.protocol.values import decode_value
from pkwbus.sim.config import SimTiming
from pkwbus.sim.drives.model import DriveModel, Limits, ModelConfig
from pkwbus.sim.drives.params import ParameterStore
from pkwbus.sim.drives.table import MODEL_PARAMS, ParamSpec

__all__ = ["CTW_LOG", "SimDrive"]

CTW_LOG = 10_000
CLOCK_PNU = 2115  # MICROMASTER 4 P2115, the AOP real-time clock

log = logging.getLogger("pkwbus.sim")


@dataclass(slots=True)
class _Job:
    """A parameter request the drive is still working on (PKW lag)."""

    request: bytes
    answer: bytes
    started: float
    seen: int = 0


class SimDrive:
    """A follower: answers its telegrams from a drive model and a parameter store."""

    def __init__(
        self,
        address: int,
        protocol: Bus,
        dialect: Dialect,
        layout: IndLayout,
        shape: BlockShape,
        specs: tuple[ParamSpec, ...],
        timing: SimTiming,
        rng: random.Random,
        config: ModelConfig | None = None,
        *,
        described: bool = True,
    ) -> None:
        """``described``: False for a drive that refuses every description request (AK 4)."""
        self.address = address
        self.dialect = dialect
        self.layout = layout
        self.shape = shape
        self.timing = timing
        self.profile = Profile.FC if protocol is Bus.FC else Profile.PROFIDRIVE
        # Where a value sits: FC always in 4 PKW words (a text, and a description's
        # name, in a block as long as it is: Danfoss FC protocol, "Read parameter
        # description"); USS by the drive's PKW length (USS specification, part C, 4.1.2).
        # (A PROFIBUS slave of the FC profile carries the PPO's 4 fixed words.)
        self.fc = protocol is Bus.FC and shape.pkw_words is None
        self.pkw_words = 4 if self.fc else shape.pkw_words
        log = max((s.array for s in specs if s.live == "alarm_code"), default=10)
        self.model = DriveModel(self.profile, rng, config or ModelConfig(), log_length=log)
        self.params = ParameterStore(specs, dialect, self._live, described=described)
        self.params.running = lambda: self.running
        if CLOCK_PNU in self.params.specs:  # a MICROMASTER 4: its fault times may be P2115's
            self.model.mm4.clock = self._clock_words
        self._steering = MODEL_PARAMS[protocol]
        self._limits = self.limits()
        self.model.setpoint = self.model.frequency = self._limits.max_frequency * 0.8
        self.requests_seen = 0
        self.control_taken = 0
        self.ctw_log: deque[bool] = deque(maxlen=CTW_LOG)  # CTW bit 10 of each request
        self.lagged = 0  # answers sent meanwhile (AK 0 or stale) while a request lagged
        self.keypad_changes = 0  # values set at the keypad
        self.last_answer: bytes | None = None  # the last telegram sent, for stale answers
        self._job: _Job | None = None
        self._last_pkw: bytes | None = None

    # ------------------------------------------------------- test surface

    def value(self, pnu: int, index: int = 0) -> int:
        """The raw value of a parameter as the drive would answer it now."""
        return self.params.value(pnu, index)

    def set_value(self, pnu: int, raw: int, index: int = 0) -> None:
        """Set a stored value directly (no checks): a test's or a demo's hand on the drive."""
        if pnu not in self.params.specs or self.params.specs[pnu].live is not None:
            raise KeyError(f"parameter {pnu} is not a stored parameter of this drive")
        self.params.raw[pnu, index] = raw

    def text(self, pnu: int) -> bytes:
        return self.params.texts[pnu]

    @property
    def eeprom(self) -> dict[tuple[int, int], int | bytes]:
        """Values written to EEPROM, by (PNU, index)."""
        return self.params.eeprom

    @property
    def running(self) -> bool:
        return self.model.frequency > 0 or (self.model.running and not self.model.tripped)

    @property
    def tripped(self) -> bool:
        return self.model.tripped

    @property
    def status_word(self) -> int:
        return self.model.status_word(self.limits())

    @property
    def mav(self) -> int:
        return self.model.mav(self.limits())

    def limits(self) -> Limits:
        """Maximum frequency and ramp times as the parameters say now, in the model's units."""
        params = self.params

        def number(role: str) -> float:
            pnu = self._steering[role]
            return params.number(pnu) / params.specs[pnu].unit_factor

        return Limits(number("max_frequency"), number("ramp_up"), number("ramp_down"))

    def tick(self, now: float) -> None:
        """Advance the model to ``now`` (the limits are read once a telegram)."""
        self._limits = self.limits()
        self.model.update(now, self._limits)

    def trip(self, code: int, now: float, value: int | None = None) -> None:
        """The drive trips at ``now`` with fault (alarm) ``code``; ``value`` for its log
        entries (default: see :meth:`DriveModel.trip`)."""
        self.tick(now)
        self.model.trip(code, value=value)

    def warn(self, bit: int | None, now: float) -> None:
        """A warning (``bit`` of the warning word) comes at ``now``, or the one there goes
        (None) (:meth:`DriveModel.warn`)."""
        self.tick(now)
        self.model.warn(bit)

    def acknowledge(self, now: float) -> None:
        """The trip is acknowledged at ``now`` (as a local operator would)."""
        self.tick(now)
        self.model.reset()

    def power_cycle(self, now: float, off: float = 0.0) -> None:
        """The drive is switched off at ``now`` and on again ``off`` seconds later
        (:meth:`DriveModel.power_cycle`)."""
        self.tick(now)
        self.model.power_cycle(off)

    def off(self, now: float) -> bool:
        """Whether the drive is switched off at ``now`` (it answers nothing then)."""
        return now < self.model.off_until

    def _clock_words(self) -> tuple[int, int, int]:
        """P2115[0..2], the AOP real-time clock, as the drive holds them now."""
        raw = self.params.raw
        return raw.get((CLOCK_PNU, 0), 0), raw.get((CLOCK_PNU, 1), 0), raw.get((CLOCK_PNU, 2), 0)

    def keypad(self, pnu: int, raw: int, index: int = 0) -> None:
        """A person at the drive's keypad (LCP) sets element ``index`` of ``pnu`` to ``raw``
        (the number on the wire): in RAM and EEPROM, with no telegram; logged. ValueError
        as :meth:`ParameterStore.keypad <pkwbus.sim.drives.params.ParameterStore.keypad>`
        (call :meth:`tick` first: whether the motor runs is the model's now)."""
        params = self.params
        before = params.raw.get((pnu, index))
        params.keypad(pnu, raw, index)
        self._limits = self.limits()  # a ramp or the maximum frequency may have changed
        self.keypad_changes += 1
        spec = params.specs[pnu]
        unit = f" {spec.unit}" if spec.unit else ""
        was = "?" if before is None else f"{_number(spec, before):g}{unit}"
        log.info(
            "drive %d: %s%s (PNU %d) set at the keypad from %s to %g%s",
            self.address, spec.name, f"[{index}]" if spec.array else "", pnu,
            was, _number(spec, raw), unit,
        )  # fmt: skip

    def _live(self, name: str, index: int) -> float:
        return self.model.quantity(name, self._limits, index)

    # ---------------------------------------------------------- telegrams

    def respond(self, data: bytes, now: float, *, broadcast: bool = False) -> bytes:
        """The data of the answer to a request's data; RemoteProtocolError if malformed."""
        block = split_block(data, self.shape)
        pkw_in = block.pkw
        if pkw_in and len(pkw_in) < 4:
            raise RemoteProtocolError(f"PKW part of {len(pkw_in)} bytes")
        self.requests_seen += 1
        if block.pzd:
            self._control(block.pzd)
        pkw_out = b""
        if pkw_in:
            pkw_out = self._pkw(pkw_in, now, broadcast=broadcast)
            self._limits = self.limits()  # a write may have changed them
        words = [self.model.status_word(self._limits), self.model.mav(self._limits)]
        words += [0] * self.shape.pzd_words
        return encode_block(pkw_out, words[: self.shape.pzd_words])

    def _control(self, words: tuple[int, ...]) -> None:
        ctw = words[0]
        taken = takes_control(ctw)
        self.ctw_log.append(taken)
        self.control_taken += taken
        self.model.received = list(words)
        self.model.apply_control(ctw, words[1] if len(words) > 1 else None, self._limits)

    def _pkw(self, pkw_in: bytes, now: float, *, broadcast: bool) -> bytes:
        try:
            req = pkw.decode_request(pkw_in, self.dialect, self.layout, self.pkw_words)
        except RemoteProtocolError:
            return self._encode(self._unknown_request(pkw_in))
        timing = self.timing
        if broadcast or req.command is Command.NONE or not timing.lagging:
            return self._answer(self._encode(self.params.execute(req)), req.command)
        job = self._job
        if job is None or job.request != pkw_in:
            job = self._job = _Job(pkw_in, self._encode(self.params.execute(req)), now)
        else:
            job.seen += 1
        if job.seen >= timing.lag_telegrams and now - job.started >= timing.lag_seconds:
            self._job = None
            return self._answer(job.answer, req.command)
        self.lagged += 1
        if timing.lag_mode == "stale" and self._last_pkw is not None:
            return self._last_pkw
        none = pkw.response_id(self.dialect, Reply.NONE)
        return self._encode(pkw.NoResponse(none, req.pnu, req.subindex))

    def _answer(self, answer: bytes, command: Command) -> bytes:
        if command is not Command.NONE:
            self._last_pkw = answer
        return answer

    def _unknown_request(self, pkw_in: bytes) -> PkwResponse:
        pke, ind = int.from_bytes(pkw_in[:2], "big"), int.from_bytes(pkw_in[2:4], "big")
        _, pnu, sub = pkw.decode_pke_ind(self.dialect, self.layout, pke, ind)
        fault = self.params.faults.unsupported
        ak = pkw.response_id(self.dialect, Reply.REJECTED)
        return Rejection(ak, pnu, sub, fault, "", "")

    def _encode(self, resp: PkwResponse) -> bytes:
        """PKW bytes of ``resp``, fitted to a fixed PKW length."""
        words = self.pkw_words
        named = isinstance(resp, pkw.DescriptionResponse) and bool(resp.data)
        fc_block = self.fc and (isinstance(resp, TextResponse) or named)
        if words is None or fc_block:
            return pkw.encode_response(resp, self.dialect, self.layout, None)
        room = 2 * words - 4
        too_wide = (
            isinstance(resp, ValueResponse | pkw.DescriptionResponse)
            and resp.width is Width.DWORD
            and room < 4
        )
        if too_wide or (isinstance(resp, TextResponse) and len(resp.text) > room):
            ak = pkw.response_id(self.dialect, Reply.REJECTED)
            resp = Rejection(ak, resp.pnu, resp.subindex, self.params.faults.channel, "", "")
        if isinstance(resp, pkw.DescriptionResponse) and named and room < 4:
            # A name in one PWE word: its first two characters.
            resp = replace(resp, raw=int.from_bytes(resp.data[:2].ljust(2, b"\0"), "big"))
        if isinstance(resp, TextResponse):
            resp = TextResponse(resp.ak, resp.pnu, resp.subindex, resp.text.ljust(room, b"\0"))
        return pkw.encode_response(resp, self.dialect, self.layout, words)


def _number(spec: ParamSpec, raw: int) -> float:
    """The engineering value of a stored raw number of ``spec``."""
    return float(decode_value(raw, spec.vtype.width or Width.DWORD, spec.vtype, spec.scaling))
