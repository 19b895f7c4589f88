"""Simulated drives for demos, tests and benchmarks: Danfoss FC and Siemens USS
followers, and PROFIBUS DP slaves (:mod:`pkwbus.sim.profibus.line`).

``Simulator`` holds the drives of one line; ``handle`` answers a request in
process, ``serve_tcp`` and ``serve_pty`` put the line on a TCP port or a
pseudo-terminal. Every answer is built with ``pkwbus.protocol``.
"""

from pkwbus.sim.config import SimFaults, SimTiming
from pkwbus.sim.drives.drive import SimDrive
from pkwbus.sim.drives.model import ModelConfig
from pkwbus.sim.drives.table import ParamSpec
from pkwbus.sim.serving.stats import SimStats
from pkwbus.sim.simulator import Simulator

__all__ = [
    "ModelConfig",
    "ParamSpec",
    "SimDrive",
    "SimFaults",
    "SimStats",
    "SimTiming",
    "Simulator",
]
