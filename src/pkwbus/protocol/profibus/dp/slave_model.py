"""What a DP master's view of one slave is made of: its states, the answers fed to it, the
events it tells, and what it is set up with (:mod:`pkwbus.protocol.profibus.dp.slave`
drives them)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from pkwbus.protocol.errors import LocalProtocolError
from pkwbus.protocol.profibus import fdl
from pkwbus.protocol.profibus.dp.services import Diagnosis, Parameters, check_cfg, io_lengths
from pkwbus.protocol.profibus.dpv1.msac import Dpv1Setup, with_dpv1
from pkwbus.protocol.profibus.dpv1.transfer import TransferEnd

__all__ = [
    "Answer",
    "DiagnosisRead",
    "Failed",
    "FailureKind",
    "Garbled",
    "Inputs",
    "NoAnswer",
    "RestartReason",
    "Restarted",
    "SlaveEvent",
    "SlaveSetup",
    "SlaveState",
    "StateChanged",
    "TransferEnded",
]


class SlaveState(enum.StrEnum):
    """The ``state`` label of pkwbus_dp_slave_state."""

    OFFLINE = "offline"
    WAIT_PRM = "wait_prm"
    WAIT_CFG = "wait_cfg"
    DATA_EXCHANGE = "data_exchange"
    LOCKED = "locked"


class RestartReason(enum.StrEnum):
    """The ``reason`` label of pkwbus_dp_restarts_total."""

    RS = "rs"
    WATCHDOG = "watchdog"
    PRM_REQUIRED = "prm_required"
    DIAG = "diag"


class FailureKind(enum.StrEnum):
    TIMEOUT = "timeout"
    GARBLED = "garbled"
    REFUSED = "refused"
    UNEXPECTED = "unexpected"


# ------------------------------------------------------------------ inputs


@dataclass(frozen=True, slots=True)
class NoAnswer:
    """Nothing came back within the slot time."""


@dataclass(frozen=True, slots=True)
class Garbled:
    """Something came back that was not a valid frame (a framing error event)."""

    detail: str = ""


Answer = fdl.Frame | NoAnswer | Garbled


# ------------------------------------------------------------------ events


@dataclass(frozen=True, slots=True)
class StateChanged:
    old: SlaveState
    new: SlaveState


@dataclass(frozen=True, slots=True)
class Restarted:
    reason: RestartReason


@dataclass(frozen=True, slots=True)
class Inputs:
    """A Data_Exchange answer: the slave's inputs (the PPO-read)."""

    data: bytes
    diagnosis_pending: bool


@dataclass(frozen=True, slots=True)
class DiagnosisRead:
    diagnosis: Diagnosis


@dataclass(frozen=True, slots=True)
class Failed:
    """One request that got no usable answer."""

    kind: FailureKind
    detail: str


@dataclass(frozen=True, slots=True)
class TransferEnded:
    """A record transfer (DP-V1) is over: its answer read back, or why not."""

    end: TransferEnd


SlaveEvent = StateChanged | Restarted | Inputs | DiagnosisRead | Failed | TransferEnded


@dataclass(frozen=True, slots=True)
class SlaveSetup:
    """What the master needs to bring one slave into data exchange."""

    address: int
    master: int
    parameters: Parameters
    cfg: bytes
    retries: int = 1
    probe_interval: float = 1.0  # seconds before the first probe of an offline or locked slave
    probe_cap: float = 30.0  # the probes' interval doubles up to this while it stays so
    dpv1: Dpv1Setup | None = None  # a DP-V1 slave: parametrised so, records over MSAC_C1

    def __post_init__(self) -> None:
        if not 0 <= self.address <= 125:
            raise LocalProtocolError(f"slave address {self.address} is outside 0-125")
        if not 0 <= self.master <= 125 or self.master == self.address:
            raise LocalProtocolError(f"master address {self.master} is not usable")
        if not 0 <= self.retries <= 8:
            raise LocalProtocolError(f"retry limit {self.retries} is outside 0-8")
        if self.probe_interval < 0 or self.probe_cap < self.probe_interval:
            raise LocalProtocolError("probe interval below 0, or above its cap")
        check_cfg(self.cfg)
        self.prm_data()

    def prm_data(self) -> bytes:
        """The Set_Prm data: with DP-V1 switched on in its first user bytes for a DP-V1 slave."""
        prm = self.parameters
        if self.dpv1 is not None:
            prm = replace(prm, user_prm=with_dpv1(prm.user_prm))
        return prm.encode()

    @property
    def inputs(self) -> int:
        return io_lengths(self.cfg)[0]

    @property
    def outputs(self) -> int:
        return io_lengths(self.cfg)[1]
